# fx_frame.gd — one binary frame of protocol fxstream.v1 (PROTOCOL.md §7), decoded with the
# engine's built-in calls only: the 64-byte header, then by kind and codec
#   kind 1 or 2, codec 16 (the engine encoding, §7.8): PoolByteArray.decompress (zstd) and
#       Image.create_from_data give `image`, half-float texels a shader samples; no loop over
#       particles or pixels;
#   kind 3, codec 1 (the light rig, §7.7): `rig`, a few dozen segments read field by field.
# Everything in a frame is checked against the bytes received and the protocol's limits
# before anything is allocated: parse() returns false with `error` saying why, and the caller
# drops the frame. Used by FxStreamClient (fx_client.gd); nothing here touches the network.
extends Reference

const HEADER_BYTES = 64
const KIND_PARTICLES = 1
const KIND_TEXTURE = 2
const KIND_LIGHT_RIG = 3
const KIND_LUT = 4
const CODEC_ENGINE = 16
const CODEC_LIGHT_RIG = 1
const ENGINE_HEADER_BYTES = 64
const ENGINE_MAX_TEXELS = 1 << 24
const ENGINE_RGBA16F = 1
const ENGINE_R16F = 2
const ENGINE_FLAG_VELOCITIES = 1
const MAX_PARTICLES = 1 << 22
const RIG_HEADER_BYTES = 32
const RIG_SEG_BYTES = 40
const RIG_CONST_FIXED = 96
const RIG_BAND_BYTES = 16
const RIG_MAX_SEG = 64
const RIG_MAX_BANDS = 8

# The frame header (PROTOCOL.md §7.1).
var kind := 0
var channel := 0
var param_rev := 0
var seq := 0
var sim_time := 0.0
var server_time_us := 0
var codec := 0
var count_or_width := 0
var height := 0
var flags := 0
# Kind 1: the particle count of the stream's frame this one is a subset of (a subscription's
# max_particles budget, PROTOCOL.md §3.5), each particle standing for total / count of them;
# 0 when the frame holds every particle (other kinds carry 0).
var total := 0

# Kinds 1 and 2 in the engine encoding: the texels as an Image (FORMAT_RGBAH, or FORMAT_RH for
# a one-channel texture). Particles: `count` texels of (x, y, z - origin, T in K), `width` a
# row, `rows` rows; with velocities the same rows again below: (vx, vy, vz, 0).
var image: Image = null
var count := 0
var width := 0
var rows := 0
var velocities := false
var origin := Vector3()
var extent := Vector3()
var channels := 0
# Kind 3: {segments: [{c, d: Vector3, a_lo, a_hi, strength: float, source, index: int}],
# constants_id: int, constants: {} or null when this frame does not carry them}.
var rig = null
# Why parse() refused the frame.
var error := ""


# Parses and decodes a whole binary message. False (with `error`) when it is not a valid
# frame, or of a kind or codec this add-on does not decode.
func parse(msg: PoolByteArray) -> bool:
	var n := msg.size()
	if n < HEADER_BYTES:
		return _fail("a binary message of %d bytes (a frame has a 64-byte header)" % n)
	if msg[0] != 0x46 or msg[1] != 0x58 or msg[2] != 0x53 or msg[3] != 0x31:
		return _fail("bad magic (not FXS1)")
	var sp := StreamPeerBuffer.new()
	sp.data_array = msg
	sp.seek(4)
	var hb := sp.get_u16()
	kind = sp.get_u16()
	channel = sp.get_u32()
	param_rev = sp.get_u32()
	seq = sp.get_u64()
	sim_time = sp.get_double()
	server_time_us = sp.get_u64()
	codec = sp.get_u32()
	var payload_bytes := sp.get_u32()
	count_or_width = sp.get_u32()
	height = sp.get_u32()
	flags = sp.get_u32()
	total = sp.get_u32()
	if hb < HEADER_BYTES or hb > n:
		return _fail("header_bytes %d outside 64..%d" % [hb, n])
	if payload_bytes != n - hb:
		return _fail("payload_bytes %d, but %d bytes follow the header" % [payload_bytes, n - hb])
	if kind == KIND_PARTICLES and total != 0 and (total < count_or_width or total > MAX_PARTICLES):
		return _fail("a subset of %d particles of a frame of %d (total: 0, or %d to %d)" % [count_or_width, total, count_or_width, MAX_PARTICLES])
	if (kind == KIND_PARTICLES or kind == KIND_TEXTURE) and codec == CODEC_ENGINE:
		return _decode_engine(sp, msg, hb, n)
	if kind == KIND_LIGHT_RIG and codec == CODEC_LIGHT_RIG:
		return _decode_rig(sp, hb, n)
	if kind == KIND_PARTICLES or kind == KIND_TEXTURE:
		return _fail("kind %d codec %d: this add-on reads the engine encoding (subscribe with encoding \"engine\")" % [kind, codec])
	return _fail("kind %d codec %d is not one this add-on decodes" % [kind, codec])


func _fail(why: String) -> bool:
	error = why
	return false


# PROTOCOL.md §7.8: a 64-byte header, then one zstd frame of raw half-float texels.
func _decode_engine(sp: StreamPeerBuffer, msg: PoolByteArray, at: int, end: int) -> bool:
	if end - at < ENGINE_HEADER_BYTES:
		return _fail("engine payload of %d bytes: shorter than its 64-byte header" % (end - at))
	if msg[at] != 0x46 or msg[at + 1] != 0x58 or msg[at + 2] != 0x45 or msg[at + 3] != 0x31:
		return _fail("engine payload: bad magic (not FXE1)")
	sp.seek(at + 4)
	var version := sp.get_u16()
	var hb := sp.get_u16()
	var format := sp.get_u16()
	var layers := sp.get_u16()
	width = sp.get_u32()
	rows = sp.get_u32()
	count = sp.get_u32()
	var raw_bytes := sp.get_u32()
	var zstd_bytes := sp.get_u32()
	origin = Vector3(sp.get_float(), sp.get_float(), sp.get_float())
	extent = Vector3(sp.get_float(), sp.get_float(), sp.get_float())
	var eflags := sp.get_u32()
	if version != 1:
		return _fail("engine payload version %d (this add-on reads 1)" % version)
	if hb < ENGINE_HEADER_BYTES or at + hb >= end:
		return _fail("engine header_bytes %d does not fit the payload" % hb)
	if format != ENGINE_RGBA16F and format != ENGINE_R16F:
		return _fail("engine texel format %d is unknown" % format)
	if eflags & ~ENGINE_FLAG_VELOCITIES:
		return _fail("engine flags %d: unknown bits" % eflags)
	velocities = eflags & ENGINE_FLAG_VELOCITIES != 0
	if layers != (2 if velocities else 1):
		return _fail("%d layers with engine flags %d" % [layers, eflags])
	var texels := width * rows * layers
	if width < 1 or rows < 1 or texels > ENGINE_MAX_TEXELS:
		return _fail("engine image %dx%d x %d layers: 1 to %d texels" % [width, rows, layers, ENGINE_MAX_TEXELS])
	var texel_bytes := 8 if format == ENGINE_RGBA16F else 2
	if raw_bytes != texels * texel_bytes:
		return _fail("raw_bytes %d for %d texels of %d bytes" % [raw_bytes, texels, texel_bytes])
	if zstd_bytes != end - at - hb:
		return _fail("zstd_bytes %d, but %d bytes follow the engine header" % [zstd_bytes, end - at - hb])
	if kind == KIND_PARTICLES:
		if format != ENGINE_RGBA16F or count > width * rows or count > MAX_PARTICLES:
			return _fail("particles: format %d, count %d in a %dx%d image" % [format, count, width, rows])
		if count != count_or_width:
			return _fail("the frame header counts %d particles, its payload %d" % [count_or_width, count])
	else:
		if layers != 1 or count != 0 or width != count_or_width or rows != height:
			return _fail("a %dx%d texture payload in a %dx%d frame" % [width, rows, count_or_width, height])
		channels = 4 if format == ENGINE_RGBA16F else 1
	var raw := msg.subarray(at + hb, end - 1).decompress(raw_bytes, File.COMPRESSION_ZSTD)
	if raw.size() != raw_bytes:
		return _fail("zstd: the texels did not decompress to raw_bytes %d (got %d)" % [raw_bytes, raw.size()])
	image = Image.new()
	image.create_from_data(width, rows * layers, false, Image.FORMAT_RGBAH if format == ENGINE_RGBA16F else Image.FORMAT_RH, raw)
	if image.is_empty():
		return _fail("Image.create_from_data refused the texels")
	return true


func _vec3(sp: StreamPeerBuffer) -> Vector3:
	return Vector3(sp.get_float(), sp.get_float(), sp.get_float())


# PROTOCOL.md §7.7, as protocol/fxs_rig.c reads it.
func _decode_rig(sp: StreamPeerBuffer, at: int, end: int) -> bool:
	var n := end - at
	if n < RIG_HEADER_BYTES:
		return _fail("light rig of %d bytes: shorter than its header" % n)
	sp.seek(at)
	if sp.get_u32() != 0x31525846:
		return _fail("light rig: bad magic (not FXR1)")
	if sp.get_u16() != 1:
		return _fail("light rig: unsupported version")
	var hb := sp.get_u16()
	var ns := sp.get_u16()
	var sb := sp.get_u16()
	var rflags := sp.get_u32()
	var constants_id := sp.get_u32()
	var cb := sp.get_u32()
	var has_constants := rflags & 1 != 0
	if hb < RIG_HEADER_BYTES or sb < RIG_SEG_BYTES or ns > RIG_MAX_SEG:
		return _fail("light rig: header %d, %d segments of %d bytes" % [hb, ns, sb])
	if (not has_constants and cb != 0) or (has_constants and cb < RIG_CONST_FIXED) or hb + ns * sb + cb != n:
		return _fail("light rig: sizes do not add up to its %d bytes" % n)
	var segments := []
	for i in range(ns):
		sp.seek(at + hb + i * sb)
		var c := _vec3(sp)
		var d := _vec3(sp)
		var a_lo := sp.get_float()
		var a_hi := sp.get_float()
		var strength := sp.get_float()
		var source := sp.get_u16()
		segments.append({"c": c, "d": d, "a_lo": a_lo, "a_hi": a_hi, "strength": strength, "source": source,
				"index": sp.get_u16()})
	var constants = null
	if has_constants:
		var c0 := at + hb + ns * sb
		sp.seek(c0)
		var nb := sp.get_u16()
		if nb < 1 or nb > RIG_MAX_BANDS or cb < RIG_CONST_FIXED + nb * RIG_BAND_BYTES:
			return _fail("light rig: %d toon bands in %d bytes of constants" % [nb, cb])
		var cf := sp.get_u16()
		constants = {"flags": cf, "strength": sp.get_float(), "outline_width": sp.get_float(),
				"outline_rgb": _vec3(sp), "shadow_theta": sp.get_float(), "shadow_opacity": sp.get_float(),
				"shadow_rgb": _vec3(sp), "plane_i": _vec3(sp), "plane_y": _vec3(sp), "plane_x": _vec3(sp),
				"plane_z": _vec3(sp), "bands": []}
		for i in range(nb):
			sp.seek(c0 + RIG_CONST_FIXED + i * RIG_BAND_BYTES)
			var m_min := sp.get_float()
			var rgb := _vec3(sp)
			constants["bands"].append({"m_min": m_min, "rgb": Color(rgb.x, rgb.y, rgb.z)})
	rig = {"segments": segments, "constants_id": constants_id, "constants": constants}
	return true
