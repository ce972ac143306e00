/* kernels.h — OpenCL C sources embedded at build time.
 *
 * tools/embed_kernels.sh turns every OpenCL file in kernels/ into a string in build/gen/kernels.c,
 * so the daemon never reads kernel files at run time. */
#ifndef FX_KERNELS_H
#define FX_KERNELS_H

/* Source text of kernels/<file>, or NULL when no such file was embedded. */
const char *kernels_source(const char *file);

#endif
