--- Lua client for the robotide Robot API (needs luasocket; JSON in robot_json.lua).
--
-- local Robot = require('robot')
-- local bot = Robot.new()               -- connects with $ROBOT_API and $ROBOT_TOKEN
-- bot:drive(0.2, 0)                     -- linear m/s, angular rad/s (clamped to the robot's limits)
-- print(bot:sensors().heading)          -- compass, degrees
-- bot:show('heading', 42)               -- appears live on the robot's page
-- bot:stop()
--
-- The robot's computer lends its senses and voice:
-- bot:say("I'm home")                   -- spoken, and shown on the robot's page
-- bot:snapshot()                        -- {jpeg = base64 text, width = .., height = ..}
-- bot:scan_barcode()                    -- {{text = 'home', format = 'QRCode', position = {...}}}
-- bot:listen(3, nil, {'move', 'stop'}).text  -- 'move', or '' when none was heard
--
-- An error the robot reports (a sensor it lacks, an unknown method) is raised with error():
-- a message string with the robot's message and code in it; bot.last_error holds it as a table
-- {code = -32000, message = '...', data = ...}. Use pcall to catch it.
--
-- JSON null is nil (a result, an object member) or Robot.null (an item of an array; pass it
-- where a nil would be lost, e.g. in a table).

local socket = require('socket')
local json = require('robot_json')

local Robot = {}
Robot.__index = Robot
Robot.json = json
Robot.null = json.null
Robot.array = json.array -- Robot.array({}) encodes as [] (an empty table encodes as {})

local function split_address(address)
  local host, port = address:match('^(.*):(%d+)$')
  if not port then
    error('bad Robot API address ' .. address .. ': expected unix:/path or host:port', 0)
  end
  if host == '' then host = '127.0.0.1' end
  return host:gsub('^%[(.*)%]$', '%1'), tonumber(port)
end

local function connect(address)
  local sock, err
  if address:sub(1, 5) == 'unix:' then
    local unix = require('socket.unix')
    sock, err = (unix.stream or unix)()
    if sock then
      local ok
      ok, err = sock:connect(address:sub(6))
      if not ok then sock:close(); sock = nil end
    end
  else
    local host, port = split_address(address)
    sock, err = socket.connect(host, port)
    if sock then sock:setoption('tcp-nodelay', true) end
  end
  if not sock then
    error('cannot reach the Robot API at ' .. address .. ': ' .. tostring(err), 0)
  end
  return sock
end

--- Connects to the robot: address and token default to $ROBOT_API and $ROBOT_TOKEN.
function Robot.new(address, token)
  address = address or os.getenv('ROBOT_API') -- unix:/path or host:port
  token = token or os.getenv('ROBOT_TOKEN')
  if not address or address == '' or not token or token == '' then
    error('ROBOT_API and ROBOT_TOKEN are not set: run this program from robotide', 2)
  end
  local self = setmetatable({ _next_id = 0, last_error = nil }, Robot)
  self._sock = connect(address)
  self:_call(3, 'auth', { n = 1, token })
  return self
end

-- One request, one reply; `level` is where error() points (the user's line). The methods
-- below keep the result in a local before returning it: a tail call would drop their frame
-- and make that level point past the user's line.
function Robot:_call(level, method, params)
  if not self._sock then error('this robot connection is closed', level) end
  self._next_id = self._next_id + 1
  local args = {}
  for i = 1, params.n do
    local value = params[i]
    if value == nil then value = json.null end
    args[i] = value
  end
  local ok, request = pcall(json.encode, {
    jsonrpc = '2.0', id = self._next_id, method = method, params = json.array(args),
  })
  if not ok then error(method .. ': ' .. request, level) end -- e.g. a NaN
  local sent, err = self._sock:send(request .. '\n')
  if not sent then
    error('cannot send to the robot: ' .. tostring(err), level)
  end
  local line
  line, err = self._sock:receive('*l')
  if not line then
    error('the robot closed the connection (the run has ended?): ' .. tostring(err), level)
  end
  local reply = json.decode(line)
  if reply.error then
    local e = reply.error
    local message = type(e.message) == 'string' and e.message or 'robot error'
    self.last_error = { code = e.code, message = message, data = e.data }
    error(string.format('robot error %s: %s', tostring(e.code), message), level)
  end
  return reply.result
end

--- Calls any Robot API method by name with positional params; returns its result.
function Robot:call(method, ...)
  local result = self:_call(3, method, table.pack(...))
  return result
end

--- Drives at `linear` m/s and `angular` rad/s; returns the speeds actually applied.
function Robot:drive(linear, angular)
  local result = self:_call(3, 'drive', table.pack(linear, angular or 0))
  return result
end

function Robot:stop()
  local result = self:_call(3, 'stop', { n = 0 })
  return result
end

--- All readings as a table: heading (deg), range (m), position {x, y, theta}, ...
function Robot:sensors()
  local result = self:_call(3, 'sensors', { n = 0 })
  return result
end

function Robot:sensor(name)
  local result = self:_call(3, 'sensor', table.pack(name))
  return result
end

function Robot:capabilities()
  local result = self:_call(3, 'capabilities', { n = 0 })
  return result
end

--- Shows a number, a text or an SVG drawing (a string starting with <svg) by name.
function Robot:show(name, value)
  local result = self:_call(3, 'show', table.pack(name, value))
  return result
end

--- Sends `value` (any JSON) to the programs subscribed to `topic`; returns how many it reached.
function Robot:publish(topic, value)
  local result = self:_call(3, 'publish', table.pack(topic, value))
  return result
end

--- From now on this connection gets the messages published on `topic`.
function Robot:subscribe(topic)
  local result = self:_call(3, 'subscribe', table.pack(topic))
  return result
end

--- The next value published on `topic`; nil after `timeout` seconds (nil: wait for ever).
function Robot:receive(topic, timeout)
  local result = self:_call(3, 'receive', table.pack(topic, timeout))
  return result
end

--- Stores `value` (any JSON) under `key` in the memory the robot's programs share.
function Robot:memory_set(key, value)
  local result = self:_call(3, 'memory_set', table.pack(key, value))
  return result
end

--- The value stored under `key`, or nil.
function Robot:memory_get(key)
  local result = self:_call(3, 'memory_get', table.pack(key))
  return result
end

--- Speaks `text` (shown on the robot's page too); returns {spoken = true or false, seconds,
--- or reason = why not}.
function Robot:say(text)
  local result = self:_call(3, 'say', table.pack(text))
  return result
end

--- The camera's frame now: {jpeg = the JPEG in base64, width = .., height = ..}.
function Robot:snapshot()
  local result = self:_call(3, 'snapshot', { n = 0 })
  return result
end

--- The barcodes and QR codes in view: an array of {text, format, position}.
function Robot:scan_barcode()
  local result = self:_call(3, 'scan_barcode', { n = 0 })
  return result
end

--- Recognises speech: `seconds` from the microphone (nil: 5), or the WAV file `wav` in the
--- program's folder; `words` (an array) listens for those only. Returns {text, words}.
function Robot:listen(seconds, wav, words)
  local result = self:_call(3, 'listen', table.pack(seconds, wav, words))
  return result
end

function Robot:close()
  if self._sock then
    self._sock:close()
    self._sock = nil
  end
end

Robot.__close = Robot.close -- local bot <close> = Robot.new()
Robot.__gc = Robot.close

return Robot
