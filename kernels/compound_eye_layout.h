/* compound_eye_layout.h — what the compound eye's host code and kernels/compound_eye.cl must
 * agree on: the optics record passed by value to every kernel and its enum values (the rays
 * per work-item are a build option: compound_eye_program). Valid C and OpenCL C: server/effects/compound_eye.h includes it, and the
 * build (tools/embed_kernels.sh) prepends it to compound_eye.cl, so the layout exists once.
 * 4-byte fields only, so host and device lay the struct out alike. */
#ifndef COMPOUND_EYE_LAYOUT_H
#define COMPOUND_EYE_LAYOUT_H

#define EYE_SQUARE 0 /* lattice */
#define EYE_HEX 1
#define EYE_SEARCH_EXACT 0 /* search: the entry lens */
#define EYE_SEARCH_SLICES 1
#define EYE_SELECT_ALL 0 /* select: the next lens */
#define EYE_SELECT_THESIS4 1
#define EYE_TIR_REFLECT 0 /* tir: total internal reflection at exit */
#define EYE_TIR_MISS 1
#define EYE_TIR_ABSORB 2

#define EYE_LANDED 0   /* a ray's status: reached the pigment plane at `land` */
#define EYE_MISSED 1   /* never reaches the pigment: upward exit (G9), or TIR policy/bounce limit */
#define EYE_ABSORBED 2 /* TIR under policy "absorb": reads as pigment */

/* What a ray cost, as the kernels write it for the host's next order (eye_order.h: the keys of
 * a counting sort, so that a work-item's rays run alike); a table sample sums its sub-rays' */
#define EYE_COST_BARE 0    /* no model surface */
#define EYE_COST_COVERED 1 /* surface seen edge-on or from behind: not traced */
#define EYE_COST_TRACED 2  /* traced, no lens entered */
#define EYE_COST_ENTERED 3 /* + the internal passes */
#define EYE_COST_MAX 255

#define EYE_SQRT3 1.7320508f /* the hex lattice's period along b, in pitches */

struct eye_optics {
    float r;        /* lens radius, pitches (digest G12: r_rel) */
    float n;        /* refractive index of the lens (air outside and below, G10) */
    float plane;    /* depth of the pigment plane below the surface, pitches */
    float tile_h;   /* lattice period along b: 1 (square) or sqrt(3) (hex) */
    int lattice;    /* EYE_SQUARE | EYE_HEX */
    int max_passes; /* l: neighbour switches allowed (G7) */
    int search;     /* EYE_SEARCH_EXACT | EYE_SEARCH_SLICES */
    int slices;     /* slice planes for EYE_SEARCH_SLICES */
    int select;     /* EYE_SELECT_ALL | EYE_SELECT_THESIS4 */
    int tir;        /* EYE_TIR_* */
    int pad0, pad1;
};

#endif
