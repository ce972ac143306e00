# fx_client.gd — FxStreamClient: a connection to fxstreamd (protocol fxstream.v1) that never
# blocks the game loop. Godot's WebSocketClient is polled once per idle frame; a host name is
# resolved on Godot's resolver thread before connecting; every reply and event comes out as a
# signal, every frame decoded by FxFrame (fx_frame.gd) as frame_received. When the connection
# drops it reconnects with backoff (reconnect_min_s doubling up to reconnect_max_s) and makes
# its subscriptions again, so a restarted daemon resumes its streams without the game doing
# anything. Requests made while disconnected wait for the next connection; one in flight when
# the connection drops gets no reply. A subscription's particle budget (max_particles) that the
# daemon refuses (cluster mode, an older daemon) is dropped for that connection: the stream is
# subscribed again without it, with budget_refused and a warning saying why.
#
# Of the frames of one stream and kind that arrive within one game frame only the newest is
# decoded (latest frame wins, as the daemon does). Frames and messages that do not follow the
# protocol are dropped with a warning (push_warning and the `warning` signal); nothing a
# server sends can stop the client.
extends Node

const FxFrame = preload("fx_frame.gd")

# The first message of each connection: {protocol, server, device, effects, encodings, limits, auth}.
signal connected(hello)
signal disconnected()
# Replies (request_id > 0) and events (request_id 0: another client's change).
signal list_received(streams, request_id)
signal described(description, request_id)
signal params(stream, rev, params, request_id)
signal created(stream, effect, rev)
signal destroyed(stream)
signal subscribed(stream, channel, encoding)
# The daemon refused a subscription's max_particles (its message): subscribed again without it,
# so its frames hold every particle until the next connection tries the budget again.
signal budget_refused(stream, message)
signal unsubscribed(stream, reason)
signal reset_done(stream, request_id)
signal presets_received(presets, request_id)
signal authenticated(role)
# An error reply (request_id of the request) or a stream's error event (stream set, request_id 0).
signal error(code, message, param, request_id, stream)
# Every decoded frame of a subscribed stream (FxFrame).
signal frame_received(stream, frame)
# A dropped frame or message, a lost connection: what push_warning printed.
signal warning(message)
# Every server message with an id, as parsed (for callers that follow their own requests).
signal reply(request_id, message)

const ENCODING_ENGINE = "engine"
const ENCODING_DEFAULT = "default"
# Requests kept while disconnected; beyond this the oldest is dropped (with a warning).
const QUEUE_MAX = 256

export var url := "ws://127.0.0.1:7681/v1/ws"
# An access token (README "Security"), sent with `auth` after hello; empty without tokens.
export var token := ""
export var autoconnect := true
export var reconnect := true
export var reconnect_min_s := 0.25
export var reconnect_max_s := 2.0
# WebSocket input buffer, KiB: at least the largest frame (a 100k-particle flame is ~0.5 MiB).
export var buffer_kb := 16384

enum State { IDLE, RESOLVING, CONNECTING, OPEN, WAITING }

var state: int = State.IDLE
var hello := {}
# Counters: frames decoded and dropped, messages dropped, connections made.
var frames_decoded := 0
var frames_dropped := 0
var messages_dropped := 0
var connections := 0
# Microseconds of this node's work in the last and the longest idle frame, and the longest
# frame decode (all of it runs in _process: polling, parsing, decoding, connecting).
var last_process_usec := 0
var max_process_usec := 0
var max_decode_usec := 0

var _ws: WebSocketClient = null
var _host := ""
var _resolve_id := -1
var _backoff := 0.0
var _retry_at := 0
var _next_id := 1
var _queue := []          # requests made while not connected: [id, op, text]
var _subs := {}           # stream -> {max_fps, encoding, max_particles, ...}: what is (re)subscribed on connect
var _channels := {}       # channel -> stream, from the subscribed replies of this connection
var _pending := {}        # id -> op of the requests sent on this connection and not answered


func _ready() -> void:
	_backoff = reconnect_min_s
	if autoconnect:
		connect_to_server()


func _exit_tree() -> void:
	close()


# Connects (or reconnects) to `to_url` (default: the url property); returns at once.
func connect_to_server(to_url := "") -> void:
	if to_url != "":
		url = to_url
	close()
	_host = _url_host(url)
	if _host == "" or _host.is_valid_ip_address():
		_open()
	else:
		_resolve_id = IP.resolve_hostname_queue_item(_host)
		state = State.RESOLVING


# Closes the connection and stops reconnecting until connect_to_server.
func close() -> void:
	if _resolve_id >= 0:
		IP.erase_resolve_item(_resolve_id)
		_resolve_id = -1
	if _ws != null:
		_ws.disconnect_from_host(1000, "client closed")
		_ws = null
	_channels.clear()
	_pending.clear()
	state = State.IDLE


func is_open() -> bool:
	return state == State.OPEN and not hello.empty()


# ---- requests (each returns its id; the reply comes as a signal with that id) ----

func list() -> int:
	return send_request("list", {})

func describe(effect: String) -> int:
	return send_request("describe", {"effect": effect})

func get_params(stream: String) -> int:
	return send_request("get", {"stream": stream})

func set_params(stream: String, changes: Dictionary) -> int:
	return send_request("set", {"stream": stream, "params": changes})

func reset(stream: String) -> int:
	return send_request("reset", {"stream": stream})

func presets(effect := "") -> int:
	return send_request("presets", {} if effect == "" else {"effect": effect})

func preset_load(stream: String, preset: String) -> int:
	return send_request("preset_load", {"stream": stream, "name": preset})


# Subscribes (again after every reconnection) to `stream`: at most max_fps steps a second (0:
# the stream's own rate), particles and textures in `encoding` ("engine": what FxFrame decodes),
# at most max_particles particles a frame (0: every particle; PROTOCOL.md §3.5: the daemon serves
# the largest step of its ladder 1000, 2000, 5000, ... at or below it, a subset each of whose
# particles stands for FxFrame.total / count; served_max_particles says which step). Made while
# disconnected, it goes out with the next connection; one the server refuses (an `error` reply
# with this id, e.g. unknown_stream) is forgotten, except a refused budget (budget_refused).
# Several users (nodes) may subscribe to one stream: the latest call's settings apply, and the
# subscription lasts until each has called unsubscribe.
func subscribe(stream: String, max_fps := 0.0, encoding := ENCODING_ENGINE, max_particles := 0) -> int:
	var id := _take_id()
	var users: int = _subs[stream]["users"] if _subs.has(stream) else 0
	_subs[stream] = {"max_fps": max_fps, "encoding": encoding, "max_particles": max_particles, "id": id,
			"sent_id": 0, "sent_budget": 0, "refused": false, "served": 0, "users": users + 1}
	if is_open():
		_send_subscribe(stream)
	return id


# Changes the particle budget of a subscription made with subscribe (0: every particle), keeping
# its other settings and users. Returns the request's id, or 0 when not subscribed to `stream`
# (or disconnected: the next connection asks for it).
func set_max_particles(stream: String, max_particles: int) -> int:
	if not _subs.has(stream):
		return 0
	_subs[stream]["max_particles"] = max_particles
	_subs[stream]["refused"] = false
	if not is_open():
		return 0
	var id := _take_id()
	_subs[stream]["id"] = id
	_send_subscribe(stream)
	return id


# The budget step the daemon serves `stream` (the latest `subscribed` reply's max_particles):
# 0 when its frames hold every particle (no budget asked, or the budget was refused).
func served_max_particles(stream: String) -> int:
	return _subs[stream]["served"] if _subs.has(stream) else 0


# Ends one user's subscription; the last one stops the stream's frames. Returns the request's
# id, or 0 when nothing is sent (other users remain, or disconnected: the next connection
# simply does not subscribe to it).
func unsubscribe(stream: String) -> int:
	if not _subs.has(stream):
		return 0
	_subs[stream]["users"] -= 1
	if _subs[stream]["users"] > 0:
		return 0
	_subs.erase(stream)
	return send_request("unsubscribe", {"stream": stream}) if is_open() else 0


# Any request: {"op": op, "id": id} + fields. Queued until connected (at most QUEUE_MAX).
func send_request(op: String, fields: Dictionary) -> int:
	var req := fields.duplicate()
	var id := _take_id()
	req["op"] = op
	req["id"] = id
	var text := to_json(req)
	if is_open():
		_send_request(id, op, text)
		return id
	if _queue.size() >= QUEUE_MAX:
		_warn("dropped the oldest of %d requests waiting for a connection (%s)" % [QUEUE_MAX, _queue[0][1]])
		_queue.pop_front()
	_queue.append([id, op, text])
	return id


func _take_id() -> int:
	_next_id += 1
	return _next_id - 1


func _send_request(id: int, op: String, text: String) -> void:
	_pending[id] = op
	_send_text(text)


# ---- the game loop ----

func _process(_delta: float) -> void:
	var t0 := OS.get_ticks_usec()
	if state == State.RESOLVING:
		_poll_resolve()
	elif state == State.WAITING and OS.get_ticks_msec() >= _retry_at:
		connect_to_server()
	elif state == State.CONNECTING or state == State.OPEN:
		var ws := _ws # holds the client while poll() may drop the connection (_lost)
		ws.poll()
		if _ws == ws:
			_drain()
	last_process_usec = OS.get_ticks_usec() - t0
	max_process_usec = max(max_process_usec, last_process_usec)


func _poll_resolve() -> void:
	var st := IP.get_resolve_item_status(_resolve_id)
	if st == IP.RESOLVER_STATUS_WAITING:
		return
	IP.erase_resolve_item(_resolve_id)
	_resolve_id = -1
	if st == IP.RESOLVER_STATUS_DONE:
		_open() # the address is in the resolver's cache now: connect_to_url does not wait
	else:
		_lost("cannot resolve %s" % _host)


func _open() -> void:
	_ws = WebSocketClient.new()
	_ws.set_buffers(buffer_kb, 4096, 1024, 4096)
	_ws.connect("connection_established", self, "_on_established")
	_ws.connect("connection_closed", self, "_on_closed")
	_ws.connect("connection_error", self, "_on_error")
	var err := _ws.connect_to_url(url, PoolStringArray(["fxstream.v1"]))
	if err != OK:
		_ws = null
		_lost("cannot connect to %s (error %d)" % [url, err])
		return
	state = State.CONNECTING


func _on_established(_protocol: String) -> void:
	state = State.OPEN
	_ws.get_peer(1).set_write_mode(WebSocketPeer.WRITE_MODE_TEXT)


func _on_closed(_was_clean: bool) -> void:
	_lost("connection to %s closed" % url)


func _on_error() -> void:
	_lost("cannot connect to %s" % url)


# The connection is gone: tell, and try again after the backoff.
func _lost(why: String) -> void:
	var was_open := not hello.empty()
	_ws = null
	hello = {}
	_channels.clear()
	_pending.clear() # requests in flight get no reply: the daemon may not have read them
	if not reconnect:
		state = State.IDLE
	else:
		state = State.WAITING
		_retry_at = OS.get_ticks_msec() + int(_backoff * 1000)
		why += "; reconnecting in %.2f s" % _backoff
		_backoff = min(_backoff * 2.0, reconnect_max_s)
	_warn(why)
	if was_open:
		emit_signal("disconnected")


func _send_text(text: String) -> void:
	_ws.get_peer(1).put_packet(text.to_utf8())


# Sends the subscription of `stream`, with the id of the subscribe call the first time (an id
# of the client's own afterwards: a refusal after a reconnection must find its subscription).
func _send_subscribe(stream: String) -> void:
	var s: Dictionary = _subs[stream]
	var req := {"op": "subscribe", "stream": stream, "encoding": s["encoding"]}
	if s["max_fps"] > 0.0:
		req["max_fps"] = s["max_fps"]
	s["sent_budget"] = 0 if s["refused"] else s["max_particles"]
	if s["sent_budget"] > 0:
		req["max_particles"] = s["sent_budget"]
	req["id"] = s["id"] if s["id"] > 0 else _take_id()
	s["sent_id"] = req["id"]
	s["id"] = 0
	_pending[req["id"]] = "subscribe"
	_send_text(to_json(req))


# The subscription whose latest subscribe request had this id, or "".
func _sub_of(id: int) -> String:
	for stream in _subs.keys():
		if _subs[stream]["sent_id"] == id:
			return stream
	return ""


# A subscribe request was refused: a refused budget is subscribed again without it (true);
# any other refusal forgets the subscription (false).
func _on_subscribe_refused(id: int, m: Dictionary) -> bool:
	var stream := _sub_of(id)
	if stream == "":
		return false
	var s: Dictionary = _subs[stream]
	if s["sent_budget"] == 0 or m.get("code") != "bad_request" or m.get("param") != "max_particles":
		_subs.erase(stream)
		return false
	var why := str(m.get("message", ""))
	s["refused"] = true
	s["served"] = 0
	_warn("%s: the daemon refused max_particles %d (%s); subscribed without a budget" % [stream, s["sent_budget"], why])
	_send_subscribe(stream)
	emit_signal("budget_refused", stream, why)
	return true


# Reads every waiting message: text at once, binary frames kept per stream and kind so only
# the newest of each is decoded.
func _drain() -> void:
	var peer := _ws.get_peer(1)
	var newest := {}
	while peer.get_available_packet_count() > 0:
		var pkt := peer.get_packet()
		if peer.was_string_packet():
			_on_text(pkt.get_string_from_utf8())
		elif pkt.size() >= 12: # keyed by the header's channel and kind
			newest[(pkt[8] | pkt[9] << 8 | pkt[10] << 16 | pkt[11] << 24) * 65536 + (pkt[6] | pkt[7] << 8)] = pkt
		else:
			_drop_frame("a binary message of %d bytes (a frame has a 64-byte header)" % pkt.size())
	for pkt in newest.values():
		_on_frame(pkt)


func _on_frame(pkt: PoolByteArray) -> void:
	var t0 := OS.get_ticks_usec()
	var f = FxFrame.new()
	if not f.parse(pkt):
		_drop_frame(f.error)
		return
	if not _channels.has(f.channel):
		_drop_frame("a frame of channel %d, which no subscription of this connection has" % f.channel)
		return
	frames_decoded += 1
	max_decode_usec = max(max_decode_usec, OS.get_ticks_usec() - t0)
	emit_signal("frame_received", _channels[f.channel], f)


func _drop_frame(why: String) -> void:
	frames_dropped += 1
	_warn("dropped a frame: " + why)


func _warn(message: String) -> void:
	push_warning("fxstream: " + message)
	emit_signal("warning", message)


func _on_text(text: String) -> void:
	var parsed := JSON.parse(text)
	if parsed.error != OK or typeof(parsed.result) != TYPE_DICTIONARY or typeof(parsed.result.get("op")) != TYPE_STRING:
		messages_dropped += 1
		_warn("dropped a message that is not a JSON object with an op: %s" % text.left(120))
		return
	var m: Dictionary = parsed.result
	var id := int(m["id"]) if typeof(m.get("id")) == TYPE_REAL else 0
	if id > 0:
		var op = _pending.get(id)
		_pending.erase(id)
		var handled: bool = op == "subscribe" and m["op"] == "error" and _on_subscribe_refused(id, m)
		emit_signal("reply", id, m)
		if handled: # a refused budget: budget_refused, not error
			return
	_dispatch(m, id)


func _dispatch(m: Dictionary, id: int) -> void:
	var op: String = m["op"]
	var stream := str(m.get("stream", ""))
	match op:
		"hello":
			_on_hello(m)
		"list":
			emit_signal("list_received", m.get("streams", []), id)
		"describe":
			emit_signal("described", m, id)
		"params":
			emit_signal("params", stream, int(m.get("rev", 0)), m.get("params", {}), id)
		"created":
			emit_signal("created", stream, str(m.get("effect", "")), int(m.get("rev", 0)))
		"destroyed":
			emit_signal("destroyed", stream)
		"subscribed":
			_channels[int(m.get("channel", 0))] = stream
			if _subs.has(stream) and _subs[stream]["sent_id"] == id:
				_subs[stream]["served"] = int(m.get("max_particles", 0))
			emit_signal("subscribed", stream, int(m.get("channel", 0)), str(m.get("encoding", ENCODING_DEFAULT)))
		"unsubscribed":
			for ch in _channels.keys():
				if _channels[ch] == stream:
					_channels.erase(ch)
			if m.has("reason"): # the stream was destroyed: nothing to subscribe to again
				_subs.erase(stream)
			emit_signal("unsubscribed", stream, str(m.get("reason", "")))
		"reset":
			emit_signal("reset_done", stream, id)
		"presets":
			emit_signal("presets_received", m.get("presets", []), id)
		"auth":
			emit_signal("authenticated", str(m.get("role", "")))
		"error":
			emit_signal("error", str(m.get("code", "")), str(m.get("message", "")), str(m.get("param", "")), id, stream)


# A new connection: authenticate, subscribe again, send what waited.
func _on_hello(m: Dictionary) -> void:
	hello = m
	connections += 1
	_backoff = reconnect_min_s
	if token != "":
		_send_text(to_json({"op": "auth", "token": token}))
	for stream in _subs.keys():
		_subs[stream]["refused"] = false # this daemon may offer budgets
		_send_subscribe(stream)
	for q in _queue:
		_send_request(q[0], q[1], q[2])
	_queue.clear()
	emit_signal("connected", hello)


# The host of a ws:// or wss:// URL ("" when it has none).
static func _url_host(u: String) -> String:
	var rest := u.split("://", true, 1)
	var hostport := (rest[1] if rest.size() > 1 else rest[0]).split("/", true, 1)[0]
	if hostport.begins_with("["):
		return hostport.substr(1, hostport.find("]") - 1)
	return hostport.split(":", true, 1)[0]
