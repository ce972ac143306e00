/* exr.h — OpenEXR files written to memory with the OpenEXR C API (OpenEXRCore).
 *
 * Texture payloads are complete EXR files so any reader (three.js EXRLoader,
 * Blender, exrheader) decodes them. Pixels are half float, scanline, row 0 at the
 * top (EXR's INCREASING_Y line order with data window origin 0,0). */
#ifndef FX_EXR_H
#define FX_EXR_H

#include <stddef.h>

#include "buf.h"
#include "err.h"

struct exr_image {
    int width, height;
    int channels;         /* 1: "Y" (luminance), 4: "R","G","B","A" */
    const float *pixels;  /* width*height*channels floats, interleaved, row 0 at the top */
    int compression;      /* one of enum exr_codec */
};

/* EXR compressions offered as the `compression` parameter, in OpenEXR's numbering. */
enum exr_codec {
    EXR_CODEC_NONE = 0,
    EXR_CODEC_RLE = 1,
    EXR_CODEC_ZIPS = 2,
    EXR_CODEC_ZIP = 3,
    EXR_CODEC_PIZ = 4,
    EXR_CODEC_PXR24 = 5,
    EXR_CODEC_B44 = 6,
    EXR_CODEC_B44A = 7,
};

/* NULL-terminated names indexed by enum exr_codec: "none","rle","zips","zip","piz",
 * "pxr24","b44","b44a". Used directly as a PARAM_ENUM choices list. */
extern const char *const exr_codec_names[];

/* Writes img as an EXR file into out (appending; out may be reused across frames to
 * avoid reallocations: reset out->len to 0 first). Returns 0, or -1 with err. */
int exr_write_mem(const struct exr_image *img, struct fx_buf *out, struct fx_err *err);

#endif
