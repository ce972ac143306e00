/* fxctl_save.h — what `fxctl subscribe` prints and writes per frame: the frame's JSON line,
 * and with --out its files: DIR/NAME-SEQ.exr (texture: codec 1 as received; the engine
 * encoding decoded with libfxclient's fxc_decode_texture and written as the EXR of its halves,
 * the payload as received in .bin), .ply (particles of either encoding, decoded with
 * fxc_decode_particles, and the payload as received in .bin), one DIR/NAME-SEQ-PROD.png per
 * look-up-table product (fxc_decode_lut), .bin for anything else, and the line in
 * DIR/NAME-SEQ.json; a light-rig frame shares its texture's SEQ, so it goes to
 * DIR/NAME-SEQ-rig.bin and .json. Decodes with fxclient.h only, like a program outside the
 * tree; EXR files are written with the daemon's writer (common/exr.h). */
#ifndef FXCTL_SAVE_H
#define FXCTL_SAVE_H

#include <stddef.h>

#include "fxclient.h"

/* Milliseconds from the frame's server time to its arrival. */
double fxctl_age_ms(const struct fxc_event *ev);

/* The frame's header as one JSON line (no newline) into buf: stream, channel, kind, seq,
 * param_rev, sim_time, server_time_us, latency_ms, codec, payload_bytes, width and height or
 * count, flags. */
void fxctl_frame_line(char *buf, size_t len, const char *stream, const struct fxc_event *ev);

/* Writes the frame's files into dir (see above). Returns 0, or -1 after printing
 * "fxctl: ..." on stderr (a payload that does not decode, a file that cannot be written). */
int fxctl_save_frame(const char *dir, const char *stream, const struct fxc_event *ev, const char *line);

#endif
