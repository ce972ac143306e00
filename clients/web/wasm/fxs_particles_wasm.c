/* fxs_particles_wasm.c — the C particle decoder (protocol/fxs_particles_dec.c) as a
 * WebAssembly module for the browser, built by make into clients/web/dist/fxs_particles.wasm
 * (clang --target=wasm32-wasi against wasi-libc; the module imports nothing).
 * clients/web/fxs_particles.js (loadWasmDecoder) drives it:
 *   p = fxs_wasm_alloc(len), the payload copied to p; fxs_wasm_decode(p, len) == 0, then
 *   the arrays at fxs_wasm_xyz() ... of fxs_wasm_n() particles (fxs_wasm_vel() 0 when the
 *   payload has no velocities), valid until the next decode; else fxs_wasm_error(), a
 *   NUL-terminated "particles: ..." message; fxs_wasm_free(p).
 * One decoder per module instance, as a worker holds one. */
#include <stdint.h>
#include <stdlib.h>

#include "fxs_particles.h"

#define FXS_WASM_EXPORT(name) __attribute__((export_name(#name)))

static struct fxs_particles fxs_wasm_out;
static char fxs_wasm_err[160];

FXS_WASM_EXPORT(fxs_wasm_alloc) void *fxs_wasm_alloc(size_t len) { return malloc(len ? len : 1); }
FXS_WASM_EXPORT(fxs_wasm_free) void fxs_wasm_free(void *p) { free(p); }

/* Decodes the payload at buf (len bytes) into the module's arrays; 0, or -1 with
 * fxs_wasm_error() set. The previous result is freed first. */
FXS_WASM_EXPORT(fxs_wasm_decode) int fxs_wasm_decode(const uint8_t *buf, size_t len)
{
    fxs_particles_free(&fxs_wasm_out);
    fxs_wasm_err[0] = 0;
    return fxs_particles_decode(buf, len, &fxs_wasm_out, fxs_wasm_err, sizeof fxs_wasm_err);
}

FXS_WASM_EXPORT(fxs_wasm_n) uint32_t fxs_wasm_n(void) { return fxs_wasm_out.n; }
FXS_WASM_EXPORT(fxs_wasm_xyz) float *fxs_wasm_xyz(void) { return fxs_wasm_out.xyz; }
FXS_WASM_EXPORT(fxs_wasm_temp) float *fxs_wasm_temp(void) { return fxs_wasm_out.temp; }
FXS_WASM_EXPORT(fxs_wasm_fuel) float *fxs_wasm_fuel(void) { return fxs_wasm_out.fuel; }
FXS_WASM_EXPORT(fxs_wasm_flags) uint8_t *fxs_wasm_flags(void) { return fxs_wasm_out.flags; }
FXS_WASM_EXPORT(fxs_wasm_vel) float *fxs_wasm_vel(void) { return fxs_wasm_out.vel; }
FXS_WASM_EXPORT(fxs_wasm_error) const char *fxs_wasm_error(void) { return fxs_wasm_err; }
