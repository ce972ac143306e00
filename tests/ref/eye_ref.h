/* eye_ref.h — double-precision C reference for the compound eye (seed 004, digest
 * digests/004-compound-eye.md), used only by tests and benches.
 *
 * It owns the ground truth the OpenCL tracer is checked against: the thesis's UV frame
 * and least-squares lift (eqs. 5.2-5.15, 5.26-5.27), the cell centre (5.17-5.22), and a
 * tracer that finds the entry lens by brute force (the smallest first root over every
 * lens in a window, accepted above depth r), then the internal pass, TIR policy and
 * landing of digest §2.9 with the §7 resolutions. It is written independently of
 * kernels/compound_eye.cl: the two agree only because both follow the digest. The
 * helpers above the tracer measure what the digest's §6 properties talk about:
 * lens-averaged darkness and pupil counts in tan-space. */
#ifndef FX_EYE_REF_H
#define FX_EYE_REF_H

struct eye_ref_optics {
    int hex;            /* 0 square, 1 hex lattice (pitch 1) */
    double r, n, plane; /* lens radius, refractive index, pigment plane depth (pitches) */
    int passes;         /* l */
    int tir;            /* 0 reflect, 1 miss, 2 absorb */
    int slices;         /* 0: exact entry; > 0: the thesis's slice search with that many steps */
    int thesis4;        /* neighbour selection restricted to the thesis's 3-lens region */
};

enum { EYE_REF_LANDED = 0, EYE_REF_MISSED = 1, EYE_REF_ABSORBED = 2 };

struct eye_ref_hit {
    int status, entered, passes, bounces;
    double land[2];
    double entry[3], entry_normal[3], r_in[3]; /* first refraction */
    double exit[3], exit_normal[3], r_out[3];  /* last refraction (when landed after a lens) */
};

/* Traces the view ray entering the surface z = 0 at (px, py) with unit direction d (d[2] < 0). */
void eye_ref_trace(const struct eye_ref_optics *o, double px, double py, const double d[3], struct eye_ref_hit *h);

/* Nearest lattice point of (x, y). */
void eye_ref_nearest(int hex, double x, double y, double c[2]);

/* Snell helper: refract unit d at unit normal m (m facing against d), ratio eta = n1/n2.
 * Returns 0 on TIR. */
int eye_ref_refract(const double d[3], const double m[3], double eta, double out[3]);

/* Pigment darkness at a landing point: 1 inside a dot of radius rho, else 0. */
double eye_ref_dark(int hex, double rho, double x, double y);

/* Lens-averaged darkness seen along view direction -w (w: towards the viewer, unit):
 * mean over an m x m grid of entry points in one lattice period; missed rays are pale
 * (0), absorbed ones dark (1). */
double eye_ref_lens_dark(const struct eye_ref_optics *o, double rho, const double w[3], int m);

/* Pupils: connected regions (4-connected) with lens-averaged darkness > 0.5 on a g x g
 * grid of viewer directions w ~ (tx, ty, 1) with |tx|, |ty| <= tmax. Writes up to
 * max centres (tan-space, darkness-weighted) into cx, cy; returns the count. */
int eye_ref_pupils(const struct eye_ref_optics *o, double rho, double tmax, int g, int m, double *cx, double *cy,
                   int max);

/* The thesis's per-triangle frame (5.4-5.15) and the least-squares lift (5.26-5.27). */
void eye_ref_uv_frame(const double P[3][3], const double T[3][2], double Pc[3], double Du[3], double Dv[3]);
void eye_ref_lift(const double Pc[3], const double Du[3], const double Dv[3], const double P[3], double *a,
                  double *b);

/* Cell centre of the thesis's piecewise rule (5.17-5.20). */
double eye_ref_cell_centre(double a);

#endif
