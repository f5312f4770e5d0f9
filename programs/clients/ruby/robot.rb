# Ruby client for the robotide Robot API (standard library only).
#
#   require 'robot'
#   bot = Robot.new
#   bot.drive(0.2, 0)            # linear m/s, angular rad/s (clamped to the robot's limits)
#   puts bot.sensors['heading']  # compass, degrees
#   bot.show('heading', 42)      # appears live on the robot's page
#   bot.stop
#
# Programs on the same robot talk through topics and a shared memory:
#   bot.subscribe('ping'); value = bot.receive('ping', 5)  # nil after 5 s
#   bot.publish('ping', { 'n' => 1 })
#   bot.memory_set('best', 3.2); bot.memory_get('best')
#
# The robot's computer lends its senses and voice:
#   bot.say("I'm home")         # spoken, and shown on the robot's page
#   bot.snapshot                # { 'jpeg' => base64 text, 'width' => .., 'height' => .. }
#   bot.scan_barcode            # [{ 'text' => 'home', 'format' => 'QRCode', 'position' => [...] }]
#   bot.listen(3, words: %w[move stop])['text'] # 'move', or '' when none was heard
#
# Any other method: bot.call('method', *params). An error the robot reports raises
# Robot::Error, with #message and #code.

require 'json'
require 'socket'

class Robot
  # An error the robot reported (e.g. a sensor it does not have), or a lost connection.
  class Error < StandardError
    attr_reader :code, :data # the JSON-RPC error code; nil for a connection error

    def initialize(message, code = nil, data = nil)
      super(message)
      @code = code
      @data = data
    end
  end

  def initialize(address = ENV['ROBOT_API'], token = ENV['ROBOT_TOKEN'])
    if address.to_s.empty? || token.to_s.empty?
      raise Error, 'ROBOT_API and ROBOT_TOKEN are not set: run this program from robotide'
    end

    @socket = connect(address)
    @next_id = 0
    call('auth', token)
  end

  def call(method, *params)
    @next_id += 1
    request = { jsonrpc: '2.0', id: @next_id, method: method, params: params }
    begin
      @socket.write(JSON.generate(request), "\n")
      line = @socket.gets
    rescue IOError, SystemCallError
      line = nil
    end
    raise Error, 'the robot closed the connection (the run has ended?)' if line.nil?

    reply = JSON.parse(line)
    if (error = reply['error'])
      raise Error.new(error['message'] || 'robot error', error['code'], error['data'])
    end
    reply['result']
  end

  # Drive at linear m/s and angular rad/s; returns the speeds actually applied.
  def drive(linear, angular = 0)
    call('drive', number(linear), number(angular))
  end

  def stop = call('stop')
  def sensors = call('sensors') # heading (deg), range (m), position {x, y, theta}, ...
  def sensor(name) = call('sensor', name)
  def capabilities = call('capabilities')
  def show(name, value) = call('show', name, value) # a number, a text or an SVG text
  def publish(topic, value) = call('publish', topic, value) # how many subscribers it reached
  def subscribe(topic) = call('subscribe', topic)
  def memory_set(key, value) = call('memory_set', key, value)
  def memory_get(key) = call('memory_get', key)

  # The next value published on topic since subscribing; nil after timeout seconds
  # (no timeout: wait for ever).
  def receive(topic, timeout = nil)
    call('receive', topic, timeout.nil? ? nil : number(timeout))
  end

  def say(text) = call('say', text) # { 'spoken' => true or false, 'seconds', or 'reason' }
  def snapshot = call('snapshot')
  def scan_barcode = call('scan_barcode')

  # Speech recognised: seconds from the microphone, or the WAV file wav in the program's
  # folder; words (an array) listens for those only. Returns { 'text', 'words' }.
  def listen(seconds = 5, wav: nil, words: nil)
    call('listen', number(seconds), wav, words)
  end

  def close
    @socket.close unless @socket.closed?
  end

  private

  def connect(address)
    if address.start_with?('unix:')
      UNIXSocket.new(address.delete_prefix('unix:'))
    else
      host, _, port = address.rpartition(':')
      socket = TCPSocket.new(host.empty? ? '127.0.0.1' : host, Integer(port))
      socket.setsockopt(Socket::IPPROTO_TCP, Socket::TCP_NODELAY, 1)
      socket
    end
  rescue SystemCallError, SocketError, ArgumentError => e
    raise Error, "cannot reach the robot at #{address}: #{e.message}"
  end

  def number(value)
    Float(value)
  rescue ArgumentError, TypeError
    raise Error, "not a number: #{value.inspect}"
  end
end
