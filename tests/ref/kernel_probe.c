/* kernel_probe.c — see kernel_probe.h. */
#include "kernel_probe.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kernels.h"
#include "ocl.h"

static int probe_set_args(struct ocl *ocl, cl_kernel k, const struct probe_arg *args, int nargs, cl_mem *mems)
{
    cl_int rc = CL_SUCCESS;
    for (int i = 0; i < nargs && rc == CL_SUCCESS; i++) {
        if (!args[i].bytes) {
            rc = clSetKernelArg(k, (cl_uint)i, args[i].value_bytes, args[i].in);
            continue;
        }
        cl_mem_flags fl = CL_MEM_READ_WRITE | (args[i].in ? CL_MEM_COPY_HOST_PTR : 0);
        mems[i] = clCreateBuffer(ocl_context(ocl), fl, args[i].bytes, (void *)args[i].in, &rc);
        if (rc == CL_SUCCESS) rc = clSetKernelArg(k, (cl_uint)i, sizeof(cl_mem), &mems[i]);
    }
    return rc;
}

/* kernels/`file` followed by tests/ref/`probe_file` as one program, built with opts (the caller
 * releases it); NULL with err. */
static cl_program probe_program(struct ocl *ocl, const char *file, const char *probe_file, const char *opts,
                                struct fx_err *err)
{
    char line[128]; /* compiler messages name the probe file's own lines */
    snprintf(line, sizeof line, "\n#line 1 \"%s\"\n", probe_file);
    const char *src[3] = {kernels_source(file), line, probe_kernels_source(probe_file)};
    if (!src[0] || !src[2]) {
        fx_fail(err, "internal", "", "%s is not embedded in this build", src[0] ? probe_file : file);
        return NULL;
    }
    cl_int rc;
    cl_device_id dev = ocl_device(ocl);
    cl_program prog = clCreateProgramWithSource(ocl_context(ocl), 3, src, NULL, &rc);
    if (rc != CL_SUCCESS) {
        fx_fail(err, "internal", "", "clCreateProgramWithSource(%s + %s): %s", file, probe_file, ocl_errstr(rc));
        return NULL;
    }
    rc = clBuildProgram(prog, 1, &dev, opts, NULL, NULL);
    if (rc != CL_SUCCESS) {
        char log[2048] = "";
        clGetProgramBuildInfo(prog, dev, CL_PROGRAM_BUILD_LOG, sizeof log - 1, log, NULL);
        fx_fail(err, "internal", "", "building %s + %s: %s: %s", file, probe_file, ocl_errstr(rc), log);
        clReleaseProgram(prog);
        return NULL;
    }
    return prog;
}

int probe_run(struct ocl *ocl, const char *file, const char *probe_file, const char *opts, const char *kernel,
              size_t global, const struct probe_arg *args, int nargs, struct fx_err *err)
{
    cl_int rc;
    cl_mem mems[16] = {0};
    if (nargs > 16) return fx_fail(err, "internal", "", "%s: too many arguments", kernel);
    /* the daemon's programs are cached by ocl; a probe program lives for this call */
    cl_program prog = probe_file ? probe_program(ocl, file, probe_file, opts, err) : ocl_program(ocl, file, opts, err);
    if (!prog) return -1;
    cl_kernel k = clCreateKernel(prog, kernel, &rc);
    if (rc != CL_SUCCESS && probe_file) clReleaseProgram(prog);
    if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "clCreateKernel(%s): %s", kernel, ocl_errstr(rc));
    rc = probe_set_args(ocl, k, args, nargs, mems);
    if (rc == CL_SUCCESS) rc = clEnqueueNDRangeKernel(ocl_queue(ocl), k, 1, NULL, &global, NULL, 0, NULL, NULL);
    for (int i = 0; i < nargs && rc == CL_SUCCESS; i++)
        if (args[i].bytes && args[i].out)
            rc = clEnqueueReadBuffer(ocl_queue(ocl), mems[i], CL_TRUE, 0, args[i].bytes, args[i].out, 0, NULL, NULL);
    for (int i = 0; i < nargs; i++)
        if (mems[i]) clReleaseMemObject(mems[i]);
    clReleaseKernel(k);
    if (probe_file) clReleaseProgram(prog);
    return rc == CL_SUCCESS ? 0 : fx_fail(err, "internal", "", "%s: %s", kernel, ocl_errstr(rc));
}

int probe_eye_trace(struct ocl *ocl, const struct eye_optics *o, int n, const float *p, const float *d,
                    struct eye_rays_out *out, struct fx_err *err)
{
    size_t bytes = (size_t)n * 4 * sizeof(float);
    float *in_p = calloc((size_t)n, 4 * sizeof(float)), *in_d = calloc((size_t)n, 4 * sizeof(float));
    float *res = malloc(bytes), *nrm = malloc(bytes);
    int rc = -1;
    if (!in_p || !in_d || !res || !nrm) {
        fx_fail(err, "internal", "", "out of memory for %d rays", n);
        goto done;
    }
    for (int i = 0; i < n; i++) {
        memcpy(in_p + 4 * i, p + 2 * i, 2 * sizeof(float));
        memcpy(in_d + 4 * i, d + 3 * i, 3 * sizeof(float));
    }
    const struct probe_arg args[] = {
        {bytes, in_p, NULL, 0}, {bytes, in_d, NULL, 0}, {bytes, NULL, res, 0}, {bytes, NULL, nrm, 0},
        {0, o, NULL, sizeof *o}, {0, &n, NULL, sizeof n},
    };
    char opts[COMPOUND_EYE_OPTS_MAX];
    size_t lanes = (size_t)compound_eye_build_options(ocl, opts), global = ((size_t)n + lanes - 1) / lanes;
    rc = probe_run(ocl, COMPOUND_EYE_CL, NULL, opts, "eye_trace_rays", global, args, 6, err);
    for (int i = 0; i < n && rc == 0; i++) {
        if (out->land) memcpy(out->land + 2 * i, res + 4 * i, 2 * sizeof(float));
        if (out->status) out->status[i] = (int)res[4 * i + 2];
        if (out->passes) out->passes[i] = (int)res[4 * i + 3];
        if (out->normal) memcpy(out->normal + 3 * i, nrm + 4 * i, 3 * sizeof(float));
        if (out->entered) out->entered[i] = (int)nrm[4 * i + 3];
    }
done:
    free(in_p);
    free(in_d);
    free(res);
    free(nrm);
    return rc;
}
