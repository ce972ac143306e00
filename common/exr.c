/* exr.c — complete scanline OpenEXR files written to memory with OpenEXRCore.
 *
 * Owns the texture payload format: one single-part scanline file per frame, half
 * channels ("Y", or "A","B","G","R" as EXR sorts them), data window (0,0)-(W-1,H-1),
 * INCREASING_Y so input row 0 is the top. OpenEXRCore writes through a custom
 * pwrite-style callback into the caller's fx_buf, so no temporary files exist and
 * the buffer can be reused frame after frame. Chunks are encoded in order with one
 * encode pipeline whose buffers are reused between chunks; the interleaved floats become
 * halves (round to nearest even, overflow to inf, NaN kept) while packed, reading straight
 * from the caller's pixels: a line at a time by the CPU's F16C instructions where it has
 * them (exr_pack_f16c, the same halves, quiet NaNs for signalling ones), else by
 * OpenEXRCore's packer. RLE chunks are compressed by exr_rle.c (the same bytes as
 * OpenEXRCore's, several times faster), in the pipeline's own buffers. Library errors are
 * captured by an error handler so the message reaches the caller instead of stderr. */
#include "exr.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <openexr.h>

#if defined(__x86_64__)
#include <cpuid.h>
#include <immintrin.h>
#endif

#include "exr_rle.h"

const char *const exr_codec_names[] = {
    "none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", NULL,
};

/* Where OpenEXRCore's writes land: out, starting at byte base. */
struct exr_sink {
    struct fx_buf *out;
    size_t base;
    char msg[256]; /* first error OpenEXRCore reported, or "" */
};

/* pwrite semantics: the offset table is written last, before the chunks. */
static int64_t exr_sink_write(exr_const_context_t ctxt, void *userdata, const void *buffer, uint64_t sz,
                              uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    struct exr_sink *sink = userdata;
    struct fx_buf *b = sink->out;
    if (offset > SIZE_MAX - sink->base - sz) {
        error_cb(ctxt, EXR_ERR_WRITE_IO, "write beyond addressable memory");
        return -1;
    }
    size_t at = sink->base + (size_t)offset, end = at + (size_t)sz;
    if (end > b->len) {
        if (fx_buf_reserve(b, end - b->len)) {
            error_cb(ctxt, EXR_ERR_OUT_OF_MEMORY, "cannot grow output to %zu bytes", end);
            return -1;
        }
        /* the offset table's gap is filled by exr_finish; zero it so that no
         * uninitialised byte could ever reach a socket */
        if (at > b->len) memset(b->data + b->len, 0, at - b->len);
        b->len = end;
    }
    memcpy(b->data + at, buffer, (size_t)sz);
    return (int64_t)sz;
}

static void exr_sink_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    void *userdata = NULL;
    if (exr_get_user_data(ctxt, &userdata) != EXR_ERR_SUCCESS || !userdata) return;
    struct exr_sink *sink = userdata;
    if (!sink->msg[0])
        snprintf(sink->msg, sizeof sink->msg, "%s: %s", exr_get_error_code_as_string(code), msg);
}

/* Index of the named channel within one interleaved R,G,B,A (or Y) pixel. */
static int exr_channel_offset(const char *name)
{
    switch (name[0]) {
    case 'G': return 1;
    case 'B': return 2;
    case 'A': return 3;
    default: return 0; /* R, Y */
    }
}

static exr_result_t exr_define_part(exr_context_t ctxt, const struct exr_image *img)
{
    static const char *const rgba[] = {"A", "B", "G", "R"}, *const luma[] = {"Y"};
    const char *const *names = img->channels == 4 ? rgba : luma;
    int part = 0;
    exr_result_t rv = exr_add_part(ctxt, NULL, EXR_STORAGE_SCANLINE, &part);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr_simple(ctxt, part, img->width, img->height,
                                                 (exr_compression_t)img->compression);
    for (int c = 0; rv == EXR_ERR_SUCCESS && c < img->channels; c++)
        rv = exr_add_channel(ctxt, part, names[c], EXR_PIXEL_HALF, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
    return rv == EXR_ERR_SUCCESS ? exr_write_header(ctxt) : rv;
}

/* Points every channel of the pipeline at rows y.. of the interleaved float input. */
static void exr_bind_channels(exr_encode_pipeline_t *pipe, const struct exr_image *img, int y)
{
    size_t row = (size_t)img->width * (size_t)img->channels;
    for (int c = 0; c < pipe->channel_count; c++) {
        exr_coding_channel_info_t *ch = &pipe->channels[c];
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = (int16_t)sizeof(float);
        ch->user_pixel_stride = (int32_t)(sizeof(float) * (size_t)img->channels);
        ch->user_line_stride = (int32_t)(sizeof(float) * row);
        ch->encode_from_ptr = (const uint8_t *)(img->pixels + (size_t)y * row + exr_channel_offset(ch->channel_name));
    }
}

/* The pipeline's buffers, all from malloc (alloc_fn and free_fn are set to these), so that
 * exr_rle_chunk can size the ones it fills. */
static void *exr_pipe_alloc(exr_transcoding_pipeline_buffer_id_t id, size_t n)
{
    (void)id;
    return malloc(n);
}

static void exr_pipe_free(exr_transcoding_pipeline_buffer_id_t id, void *p)
{
    (void)id;
    free(p);
}

/* A buffer of the pipeline at least n bytes long (its contents dropped). */
static int exr_pipe_reserve(void **buf, size_t *size, size_t n)
{
    if (*buf && *size >= n) return 0;
    free(*buf);
    *size = 0;
    if (!(*buf = malloc(n))) return -1;
    *size = n;
    return 0;
}

/* The pipeline's compress_fn for RLE. */
static exr_result_t exr_rle_chunk(exr_encode_pipeline_t *pipe)
{
    size_t n = pipe->packed_bytes;
    if (exr_pipe_reserve(&pipe->compressed_buffer, &pipe->compressed_alloc_size, EXR_RLE_OUT(n)) ||
        exr_pipe_reserve(&pipe->scratch_buffer_1, &pipe->scratch_alloc_size_1, n))
        return EXR_ERR_OUT_OF_MEMORY;
    pipe->compressed_bytes = exr_rle_compress(pipe->packed_buffer, n, pipe->scratch_buffer_1, pipe->compressed_buffer);
    return EXR_ERR_SUCCESS;
}

#if defined(__x86_64__)
/* n floats to halves, 8 at a time (round to nearest even). */
__attribute__((target("avx,f16c"))) static void exr_halves_f16c(const float *in, uint16_t *out, size_t n)
{
    size_t i = 0;
    for (; i + 8 <= n; i += 8)
        _mm_storeu_si128((__m128i *)(out + i), _mm256_cvtps_ph(_mm256_loadu_ps(in + i), _MM_FROUND_TO_NEAREST_INT));
    for (; i < n; i++) out[i] = _cvtss_sh(in[i], _MM_FROUND_TO_NEAREST_INT);
}

/* The pipeline's convert_and_pack_fn on F16C CPUs: each line of the chunk converted whole
 * (its channels interleaved, as the caller's pixels are), then each channel's halves laid out
 * in the pipeline's channel order, line after line as OpenEXR packs a scanline chunk. */
static exr_result_t exr_pack_f16c(exr_encode_pipeline_t *pipe)
{
    const exr_coding_channel_info_t *ch = pipe->channels;
    const int nch = pipe->channel_count, width = ch[0].width;
    const uint8_t *row = ch[0].encode_from_ptr; /* the chunk's first pixel: its first channel in memory */
    for (int c = 1; c < nch; c++) row = ch[c].encode_from_ptr < row ? ch[c].encode_from_ptr : row;
    size_t line = (size_t)width * (size_t)nch, at[4]; /* 1 or 4 channels (exr_check_image) */
    if (exr_pipe_reserve(&pipe->scratch_buffer_2, &pipe->scratch_alloc_size_2, line * sizeof(uint16_t)))
        return EXR_ERR_OUT_OF_MEMORY;
    for (int c = 0; c < nch; c++) at[c] = (size_t)(ch[c].encode_from_ptr - row) / sizeof(float);
    uint16_t *h = pipe->scratch_buffer_2, *dst = pipe->packed_buffer;
    for (int y = 0; y < pipe->chunk.height; y++, row += ch[0].user_line_stride) {
        exr_halves_f16c((const float *)row, h, line);
        for (int c = 0; c < nch; c++, dst += width)
            for (int x = 0; x < width; x++) dst[x] = h[(size_t)x * (size_t)nch + at[c]];
    }
    pipe->packed_bytes = (uint64_t)((uint8_t *)dst - (uint8_t *)pipe->packed_buffer);
    return EXR_ERR_SUCCESS;
}
#endif

/* The packer for img's chunks: exr_pack_f16c where the CPU has F16C, else OpenEXRCore's. */
static void exr_choose_pack(exr_encode_pipeline_t *pipe)
{
#if defined(__x86_64__)
    unsigned a, b, c, d; /* F16C: CPUID leaf 1 (the compilers' cpu_supports do not all name it) */
    if (__builtin_cpu_supports("avx") && __get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C))
        pipe->convert_and_pack_fn = exr_pack_f16c;
#else
    (void)pipe;
#endif
}

static exr_result_t exr_encode_chunk(exr_context_t ctxt, const struct exr_image *img, int y,
                                     exr_encode_pipeline_t *pipe)
{
    exr_chunk_info_t cinfo;
    int first = pipe->channels == NULL;
    exr_result_t rv = exr_write_scanline_chunk_info(ctxt, 0, y, &cinfo);
    if (rv != EXR_ERR_SUCCESS) return rv;
    rv = first ? exr_encoding_initialize(ctxt, 0, &cinfo, pipe) : exr_encoding_update(ctxt, 0, &cinfo, pipe);
    if (rv != EXR_ERR_SUCCESS) return rv;
    exr_bind_channels(pipe, img, y);
    if (first) {
        rv = exr_encoding_choose_default_routines(ctxt, 0, pipe);
        pipe->alloc_fn = exr_pipe_alloc;
        pipe->free_fn = exr_pipe_free;
        exr_choose_pack(pipe);
        if (img->compression == EXR_CODEC_RLE) pipe->compress_fn = exr_rle_chunk;
    }
    return rv == EXR_ERR_SUCCESS ? exr_encoding_run(ctxt, 0, pipe) : rv;
}

static exr_result_t exr_write_chunks(exr_context_t ctxt, const struct exr_image *img)
{
    exr_encode_pipeline_t pipe = EXR_ENCODE_PIPELINE_INITIALIZER;
    int32_t lines = 0;
    exr_result_t rv = exr_get_scanlines_per_chunk(ctxt, 0, &lines);
    for (int y = 0; rv == EXR_ERR_SUCCESS && y < img->height; y += lines)
        rv = exr_encode_chunk(ctxt, img, y, &pipe);
    if (pipe.channels) exr_encoding_destroy(ctxt, &pipe);
    return rv;
}

static int exr_check_image(const struct exr_image *img, struct fx_err *err)
{
    if (!img->pixels || img->width <= 0 || img->height <= 0)
        return fx_fail(err, "internal", NULL, "EXR image %dx%d without pixels", img->width, img->height);
    if (img->channels != 1 && img->channels != 4)
        return fx_fail(err, "internal", NULL, "EXR image with %d channels (1 or 4 supported)", img->channels);
    if (img->compression < EXR_CODEC_NONE || img->compression > EXR_CODEC_B44A)
        return fx_fail(err, "internal", NULL, "unknown EXR compression %d", img->compression);
    return 0;
}

int exr_write_mem(const struct exr_image *img, struct fx_buf *out, struct fx_err *err)
{
    if (exr_check_image(img, err)) return -1;
    struct exr_sink sink = {.out = out, .base = out->len};
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.user_data = &sink;
    init.write_fn = exr_sink_write;
    init.error_handler_fn = exr_sink_error;
    exr_context_t ctxt = NULL;
    exr_result_t rv = exr_start_write(&ctxt, "fxstream.exr", EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS) rv = exr_define_part(ctxt, img);
    if (rv == EXR_ERR_SUCCESS) rv = exr_write_chunks(ctxt, img);
    if (ctxt) {
        exr_result_t done = exr_finish(&ctxt);
        if (rv == EXR_ERR_SUCCESS) rv = done;
    }
    if (rv == EXR_ERR_SUCCESS) return 0;
    out->len = sink.base;
    return fx_fail(err, "internal", NULL, "EXR %dx%d %s: %s", img->width, img->height,
                   exr_codec_names[img->compression], sink.msg[0] ? sink.msg : exr_get_default_error_message(rv));
}
