-- robot_json: a small, strict JSON encoder and decoder for the Lua Robot API client.
--
-- local json = require('robot_json')
-- json.encode({speed = 0.2, tags = {'a', 'b'}})   --> '{"speed":0.2,"tags":["a","b"]}'
-- json.decode('[1, null, "\\u00e9"]')              --> {1, json.null, 'é'}
--
-- Mapping:
--   JSON null    <-> nil at the top level and as an object member (the key is absent);
--                    json.null inside arrays, so an array keeps its length. json.null
--                    also encodes as null anywhere.
--   true/false   <-> booleans
--   numbers      <-> integers (JSON numbers without fraction or exponent that fit) or floats
--   strings      <-> Lua strings in UTF-8 (\uXXXX escapes and surrogate pairs decoded)
--   arrays       <-> tables with keys 1..n (decoded arrays carry json.array's metatable, so
--                    an empty one stays an array when encoded again)
--   objects      <-> tables with string keys; an empty table encodes as {} unless
--                    wrapped with json.array({})

local json = {}

local null = setmetatable({}, {
  __tostring = function() return 'null' end,
  __name = 'json.null',
})
json.null = null

local array_mt = { __name = 'json.array' }

-- Marks a table as a JSON array (needed only for empty ones); returns it.
function json.array(t)
  return setmetatable(t or {}, array_mt)
end

function json.is_array(t)
  return getmetatable(t) == array_mt
end

---------------------------------------------------------------------------------------------
-- encoding

local escapes = {
  ['"'] = '\\"', ['\\'] = '\\\\', ['\b'] = '\\b', ['\f'] = '\\f',
  ['\n'] = '\\n', ['\r'] = '\\r', ['\t'] = '\\t',
}

local function escape_char(c)
  return escapes[c] or string.format('\\u%04x', c:byte())
end

local function encode_string(s)
  if not utf8.len(s) then
    error('cannot encode a string that is not valid UTF-8 as JSON', 0)
  end
  return '"' .. s:gsub('[%c"\\]', escape_char) .. '"'
end

local function encode_number(n)
  if math.type(n) == 'integer' then
    return string.format('%d', n)
  end
  if n ~= n or n == math.huge or n == -math.huge then
    error('cannot encode ' .. tostring(n) .. ' as JSON (only finite numbers)', 0)
  end
  local text
  for digits = 15, 17 do -- the shortest text that reads back as the same number
    text = string.format('%.' .. digits .. 'g', n)
    if tonumber(text) == n then break end
  end
  if not text:find('[.eE]') then
    text = text .. '.0' -- keep a float a float
  end
  return text
end

local encode_value

local function encode_table(t, out, seen)
  if seen[t] then
    error('cannot encode a table that contains itself as JSON', 0)
  end
  seen[t] = true
  local count, max_index, string_keys = 0, 0, false
  for k in pairs(t) do
    count = count + 1
    if math.type(k) == 'integer' and k > 0 then
      if k > max_index then max_index = k end
    elseif type(k) == 'string' then
      string_keys = true
    else
      error('cannot encode a table key of type ' .. (math.type(k) or type(k)) .. ' as JSON', 0)
    end
  end
  if string_keys and max_index > 0 then
    error('cannot encode a table with both array items and named keys as JSON', 0)
  end
  if string_keys or (count == 0 and getmetatable(t) ~= array_mt) then
    local keys = {}
    for k in pairs(t) do keys[#keys + 1] = k end
    table.sort(keys) -- a stable output
    out[#out + 1] = '{'
    for i, k in ipairs(keys) do
      if i > 1 then out[#out + 1] = ',' end
      out[#out + 1] = encode_string(k)
      out[#out + 1] = ':'
      encode_value(t[k], out, seen)
    end
    out[#out + 1] = '}'
  else
    if max_index > 2 * count + 16 then
      error('cannot encode a sparse table (' .. count .. ' items, last index ' .. max_index
        .. ') as a JSON array', 0)
    end
    out[#out + 1] = '['
    for i = 1, max_index do
      if i > 1 then out[#out + 1] = ',' end
      encode_value(t[i], out, seen) -- a hole is null
    end
    out[#out + 1] = ']'
  end
  seen[t] = nil
end

function encode_value(v, out, seen)
  local kind = type(v)
  if v == nil or v == null then
    out[#out + 1] = 'null'
  elseif kind == 'boolean' then
    out[#out + 1] = v and 'true' or 'false'
  elseif kind == 'number' then
    out[#out + 1] = encode_number(v)
  elseif kind == 'string' then
    out[#out + 1] = encode_string(v)
  elseif kind == 'table' then
    encode_table(v, out, seen)
  else
    error('cannot encode a ' .. kind .. ' as JSON', 0)
  end
end

-- Returns the JSON text of `value` (one line: strings escape their newlines).
function json.encode(value)
  local out = {}
  encode_value(value, out, {})
  return table.concat(out)
end

---------------------------------------------------------------------------------------------
-- decoding

local unescapes = {
  ['"'] = '"', ['\\'] = '\\', ['/'] = '/', b = '\b', f = '\f', n = '\n', r = '\r', t = '\t',
}

local function fail(text, pos, what)
  local line = select(2, text:sub(1, pos):gsub('\n', '')) + 1
  error(string.format('invalid JSON at character %d (line %d): %s', pos, line, what), 0)
end

local function skip_space(text, pos)
  return text:find('[^ \t\r\n]', pos) or #text + 1
end

local decode_value

local function decode_string(text, pos)
  -- text:sub(pos, pos) == '"'
  local parts = {}
  local i = pos + 1
  while true do
    local stop = text:find('["\\%c]', i)
    if not stop then fail(text, pos, 'unterminated string') end
    parts[#parts + 1] = text:sub(i, stop - 1)
    local c = text:sub(stop, stop)
    if c == '"' then
      local s = table.concat(parts)
      if not utf8.len(s) then fail(text, pos, 'a string that is not valid UTF-8') end
      return s, stop + 1
    elseif c == '\\' then
      local e = text:sub(stop + 1, stop + 1)
      if e == 'u' then
        local hex = text:match('^%x%x%x%x', stop + 2)
        if not hex then fail(text, stop, 'bad \\u escape') end
        local code = tonumber(hex, 16)
        i = stop + 6
        if code >= 0xD800 and code <= 0xDBFF then
          local low = text:match('^\\u(%x%x%x%x)', i)
          low = low and tonumber(low, 16)
          if low and low >= 0xDC00 and low <= 0xDFFF then
            code = 0x10000 + (code - 0xD800) * 0x400 + (low - 0xDC00)
            i = i + 6
          else
            code = 0xFFFD -- a lone surrogate
          end
        elseif code >= 0xDC00 and code <= 0xDFFF then
          code = 0xFFFD
        end
        parts[#parts + 1] = utf8.char(code)
      else
        local u = unescapes[e]
        if not u then fail(text, stop, 'bad escape \\' .. e) end
        parts[#parts + 1] = u
        i = stop + 2
      end
    else
      fail(text, stop, 'a control character inside a string')
    end
  end
end

local function decode_number(text, pos)
  local int = text:match('^-?%d+', pos)
  if not int or int:match('^-?0%d') then fail(text, pos, 'bad number') end
  local stop = pos + #int
  local frac = text:match('^%.%d+', stop) or ''
  if frac == '' and text:sub(stop, stop) == '.' then fail(text, stop, 'bad number') end
  stop = stop + #frac
  local exp = text:match('^[eE][-+]?%d+', stop) or ''
  if exp == '' and text:find('^[eE]', stop) then fail(text, stop, 'bad number') end
  stop = stop + #exp
  local value
  if frac == '' and exp == '' then
    value = math.tointeger(tonumber(int)) or tonumber(int .. '.0') -- too big: a float
  else
    value = tonumber(int .. frac .. exp) + 0.0
  end
  return value, stop
end

local literals = { ['true'] = true, ['false'] = false }

function decode_value(text, pos, depth)
  if depth > 512 then fail(text, pos, 'nested too deeply') end
  pos = skip_space(text, pos)
  local c = text:sub(pos, pos)
  if c == '{' then
    local object = {}
    pos = skip_space(text, pos + 1)
    if text:sub(pos, pos) == '}' then return object, pos + 1 end
    while true do
      if text:sub(pos, pos) ~= '"' then fail(text, pos, 'expected a member name') end
      local key
      key, pos = decode_string(text, pos)
      pos = skip_space(text, pos)
      if text:sub(pos, pos) ~= ':' then fail(text, pos, "expected ':'") end
      local value
      value, pos = decode_value(text, pos + 1, depth + 1)
      if value == null then value = nil end -- a null member: the key is absent
      object[key] = value
      pos = skip_space(text, pos)
      c = text:sub(pos, pos)
      if c == '}' then return object, pos + 1 end
      if c ~= ',' then fail(text, pos, "expected ',' or '}'") end
      pos = skip_space(text, pos + 1)
    end
  elseif c == '[' then
    local list, n = json.array({}), 0
    pos = skip_space(text, pos + 1)
    if text:sub(pos, pos) == ']' then return list, pos + 1 end
    while true do
      local value
      value, pos = decode_value(text, pos, depth + 1)
      n = n + 1
      list[n] = value -- null stays json.null: the array keeps its length
      pos = skip_space(text, pos)
      c = text:sub(pos, pos)
      if c == ']' then return list, pos + 1 end
      if c ~= ',' then fail(text, pos, "expected ',' or ']'") end
      pos = pos + 1
    end
  elseif c == '"' then
    return decode_string(text, pos)
  elseif c == '-' or c:match('%d') then
    return decode_number(text, pos)
  else
    local word = text:match('^%a+', pos)
    if word == 'null' then return null, pos + 4 end
    if literals[word] ~= nil then return literals[word], pos + #word end
    fail(text, pos, c == '' and 'unexpected end' or 'unexpected ' .. (word or c))
  end
end

-- Returns the value of the JSON text (null at the top level: nil). Raises an error on bad JSON.
function json.decode(text)
  if type(text) ~= 'string' then error('json.decode expects a string', 2) end
  local value, pos = decode_value(text, 1, 0)
  pos = skip_space(text, pos)
  if pos <= #text then fail(text, pos, 'trailing characters') end
  if value == null then return nil end
  return value
end

return json
