/* compound_eye.cl — effect `compound_eye` (seed 004, Sagawa 2014; spec: digest 004).
 *
 * One tracing core, eye_trace(), shared by every kernel: a view ray that meets the
 * surface at in-cell position p (tangent space, lengths in lattice pitches, surface at
 * z = 0, outward normal +z) enters the layer of overlapping lens spheres (radius r,
 * centres r below the cell centres, eq. 5.22), refracts in, passes straight through up
 * to `max_passes` overlapping neighbours (the thesis's internal pass, §2.6), refracts
 * out and lands on the pigment plane z = -plane (digest §2.9). The drivers are
 * eye_lut (the lens look-up table: in-cell position x view direction, digest §8.1),
 * eye_bake (a view texture over a model's UV atlas, §8.2) and eye_trace_rays (raw
 * landings, for the tests and the benchmark).
 *
 * The host (server/effects/compound_eye.c, eye_lut.c) mirrors struct eye_optics and the
 * EYE_* constants; tests/ref/eye_ref.c is the independent double-precision reference. */

#define EYE_SQUARE 0
#define EYE_HEX 1
#define EYE_SEARCH_EXACT 0
#define EYE_SEARCH_SLICES 1
#define EYE_SELECT_ALL 0
#define EYE_SELECT_THESIS4 1
#define EYE_TIR_REFLECT 0
#define EYE_TIR_MISS 1
#define EYE_TIR_ABSORB 2

#define EYE_LANDED 0   /* reached the pigment plane at `land` */
#define EYE_MISSED 1   /* never reaches the pigment: upward exit (G9), or TIR policy/bounce limit */
#define EYE_ABSORBED 2 /* TIR under policy "absorb": reads as pigment */

#define EYE_MAX_BOUNCES 4 /* digest §7 G8: reflect at most 4 times, then count a miss */
#define EYE_WALK_MAX 96   /* Voronoi cells walked looking for the entry lens */
#define EYE_SQRT3 1.7320508f

/* Mirrors struct eye_optics in server/effects/compound_eye.h: 4-byte fields only. */
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

struct eye_hit {
    float2 land;   /* landing point on the pigment plane, pitches (valid when EYE_LANDED) */
    float3 normal; /* outward lens normal at the entry point (0,0,1 when no lens was hit) */
    int status;
    int entered;   /* 1 when the ray entered a lens */
    int passes;    /* neighbour switches taken */
};

/* ---- lattice ----------------------------------------------------------------------- */
/* Lattice points are o + i*(1,0) + j*e2: square o=(1/2,1/2), e2=(0,1) (cell centres, eqs.
 * 5.17-5.20 = floor+1/2, G4); hex o=(1/2,sqrt3/4), e2=(1/2,sqrt3/2) (G18), pitch 1. */

inline float2 eye_origin(int lattice) { return lattice == EYE_HEX ? (float2)(0.5f, 0.25f * EYE_SQRT3) : (float2)(0.5f, 0.5f); }
inline float2 eye_e2(int lattice) { return lattice == EYE_HEX ? (float2)(0.5f, 0.5f * EYE_SQRT3) : (float2)(0.0f, 1.0f); }

/* Nearest lattice point (the Voronoi cell containing q): the lens whose cap is the top of
 * the lens layer above q. Hex: the closer of the two rectangular sub-lattices. */
inline float2 eye_nearest(int lattice, float2 q)
{
    if (lattice != EYE_HEX) return floor(q) + 0.5f;
    const float2 per = (float2)(1.0f, EYE_SQRT3);
    float2 a0 = (float2)(0.5f, 0.25f * EYE_SQRT3), b0 = (float2)(0.0f, 0.75f * EYE_SQRT3);
    float2 a = a0 + per * rint((q - a0) / per), b = b0 + per * rint((q - b0) / per);
    float2 da = q - a, db = q - b;
    return dot(da, da) <= dot(db, db) ? a : b;
}

/* Unit vectors to the Voronoi neighbours (all at distance 1 = one pitch). */
__constant float2 eye_square_walls[4] = {(float2)(1.0f, 0.0f), (float2)(0.0f, 1.0f), (float2)(-1.0f, 0.0f),
                                         (float2)(0.0f, -1.0f)};
__constant float2 eye_hex_walls[6] = {(float2)(1.0f, 0.0f), (float2)(0.5f, 0.8660254f), (float2)(-0.5f, 0.8660254f),
                                      (float2)(-1.0f, 0.0f), (float2)(-0.5f, -0.8660254f), (float2)(0.5f, -0.8660254f)};

/* Ray o + t d (d unit) against the sphere (c, r): the two roots, or false. */
inline bool eye_roots(float3 o, float3 d, float3 c, float r, float *t1, float *t2)
{
    float3 oc = o - c;
    float b = dot(oc, d), disc = b * b - (dot(oc, oc) - r * r);
    if (disc < 0.0f) return false;
    float s = sqrt(disc);
    *t1 = -b - s;
    *t2 = -b + s;
    return true;
}

/* ---- entry lens (digest §2.4, G3) -------------------------------------------------- */

/* Exact: walk the Voronoi cells the ray's projection crosses. Inside one cell the top of
 * the (equal, equally deep) lens layer is that cell's sphere, so the first root found
 * within the cell's stretch of the ray is the first lens hit. The walk ends at depth r,
 * where the thesis stops looking (§2.4): below it the ray goes on unrefracted. */
static bool eye_enter_exact(const struct eye_optics *o, float2 p, float3 d, float3 *c_out, float *t_out)
{
    const float r = o->r;
    const float tmax = r / -d.z; /* the ray is at depth r */
    float2 c = eye_nearest(o->lattice, p), dh = d.xy;
    const int nn = o->lattice == EYE_HEX ? 6 : 4;
    float t_in = 0.0f;
    for (int k = 0; k < EYE_WALK_MAX && t_in <= tmax; k++) {
        float t1, t2;
        float3 c3 = (float3)(c, -r);
        float t_exit = INFINITY;
        float2 step = (float2)(0.0f);
        for (int e = 0; e < nn; e++) { /* the cell's walls: bisectors to its Voronoi neighbours */
            float2 v = o->lattice == EYE_HEX ? eye_hex_walls[e] : eye_square_walls[e];
            float den = dot(dh, v);
            if (den <= 1e-9f) continue;
            float t = (dot(c - p, v) + 0.5f) / den;
            if (t < t_exit) { t_exit = t; step = v; }
        }
        if (eye_roots((float3)(p, 0.0f), d, c3, r, &t1, &t2) && t2 >= t_in && t1 <= t_exit) {
            float t = fmax(t1, 0.0f);
            if (t > tmax) return false;
            *c_out = c3;
            *t_out = t;
            return true;
        }
        t_in = t_exit;
        c = eye_nearest(o->lattice, c + step); /* snap, so rounding never drifts off-lattice */
    }
    return false;
}

/* The thesis's slice planes (eqs. 5.23-5.27): at depths h = 0, r/s, ..., r take the lens
 * whose cell contains the ray's point at depth h lifted back to the surface; the first
 * one the ray meets is the entry lens. */
static bool eye_enter_slices(const struct eye_optics *o, float2 p, float3 d, float3 *c_out, float *t_out)
{
    const float r = o->r;
    for (int s = 0; s <= o->slices; s++) {
        float t = r * (float)s / (float)o->slices / -d.z;
        float3 c3 = (float3)(eye_nearest(o->lattice, p + d.xy * t), -r);
        float t1, t2;
        if (eye_roots((float3)(p, 0.0f), d, c3, r, &t1, &t2) && t2 >= 0.0f) {
            *c_out = c3;
            *t_out = fmax(t1, 0.0f);
            return true;
        }
    }
    return false;
}

/* ---- internal pass (digest §2.6, G5, G6) ------------------------------------------- */

/* thesis4 (Fig. 5.10): only the three neighbours of the region R_dir points into. */
static bool eye_thesis4(int lattice, float2 dc, float2 dir)
{
    if (lattice == EYE_HEX) return dot(dc, dc) < 1.5f && dot(dc, dir) > 0.0f;
    float2 a = fabs(dir);
    int ix = (int)rint(dc.x), iy = (int)rint(dc.y);
    if (a.x >= a.y) return ix == (dir.x > 0.0f ? 1 : -1) && abs(iy) <= 1;
    return iy == (dir.y > 0.0f ? 1 : -1) && abs(ix) <= 1;
}

/* From the far root tf of lens *c on the ray (org, dir): while the far point lies inside
 * other lenses, move to the one whose own far root is farthest (G5), on the same unbent
 * ray (G6); each move counts one pass against l. */
static float eye_inner_pass(const struct eye_optics *o, float3 org, float3 dir, float3 *c, float tf, int *passes)
{
    const float r = o->r, r2 = r * r;
    const float2 o0 = eye_origin(o->lattice), e2 = eye_e2(o->lattice);
    while (*passes < o->max_passes) {
        float3 f = org + dir * tf;
        float dz = f.z + r, rho2 = r2 - dz * dz;
        if (rho2 <= 0.0f) break;
        float rho = sqrt(rho2), best_t = tf * (1.0f + 1e-6f) + 1e-6f;
        float3 best = *c;
        int j0 = (int)ceil((f.y - o0.y - rho) / e2.y), j1 = (int)floor((f.y - o0.y + rho) / e2.y);
        for (int j = j0; j <= j1; j++) {
            float x0 = o0.x + e2.x * (float)j, y = o0.y + e2.y * (float)j;
            int i0 = (int)ceil(f.x - x0 - rho), i1 = (int)floor(f.x - x0 + rho);
            for (int i = i0; i <= i1; i++) {
                float3 cn = (float3)(x0 + (float)i, y, -r);
                float3 q = f - cn;
                if (dot(q, q) >= r2) continue;
                float2 dc = cn.xy - c->xy;
                if (dot(dc, dc) < 1e-4f) continue; /* the current lens itself */
                if (o->select == EYE_SELECT_THESIS4 && !eye_thesis4(o->lattice, dc, dir.xy)) continue;
                float t1, t2;
                if (eye_roots(org, dir, cn, r, &t1, &t2) && t2 > best_t) { best_t = t2; best = cn; }
            }
        }
        if (best_t <= tf * (1.0f + 1e-6f) + 1e-6f) break;
        *c = best;
        tf = best_t;
        (*passes)++;
    }
    return tf;
}

/* ---- the core ---------------------------------------------------------------------- */

/* d: unit view direction (towards the surface, d.z < 0); p: in-cell entry point. */
static struct eye_hit eye_trace(const struct eye_optics *o, float2 p, float3 d)
{
    struct eye_hit h = {(float2)(0.0f), (float3)(0.0f, 0.0f, 1.0f), EYE_LANDED, 0, 0};
    float3 c, org, dir = d;
    float t;
    bool in = o->search == EYE_SEARCH_SLICES ? eye_enter_slices(o, p, d, &c, &t) : eye_enter_exact(o, p, d, &c, &t);
    if (!in) { /* §2.4: no lens down to depth r, the ray goes on unrefracted */
        h.land = p + d.xy * (o->plane / -d.z);
        return h;
    }
    h.entered = 1;
    org = (float3)(p, 0.0f) + d * t;
    float3 nn = (org - c) / o->r; /* eq. 5.28 */
    h.normal = nn;
    float eta = 1.0f / o->n, ci = -dot(nn, d);
    dir = normalize(eta * d + (eta * ci - sqrt(fmax(0.0f, 1.0f - eta * eta * (1.0f - ci * ci)))) * nn);
    float t1, tf;
    if (!eye_roots(org, dir, c, o->r, &t1, &tf)) tf = 0.0f;
    for (int bounce = 0;; bounce++) {
        tf = eye_inner_pass(o, org, dir, &c, tf, &h.passes);
        float3 f = org + dir * tf, nf = (f - c) / o->r;
        float cosi = dot(dir, nf), k = 1.0f - o->n * o->n * (1.0f - cosi * cosi);
        if (k >= 0.0f) { /* refract out: GLSL refract(dir, -nf, n) */
            float3 out = o->n * dir - (o->n * cosi - sqrt(k)) * nf;
            if (out.z >= -1e-6f) { h.status = EYE_MISSED; return h; } /* G9 */
            h.land = f.xy + out.xy * ((-o->plane - f.z) / out.z);
            return h;
        }
        /* G8: total internal reflection, which the thesis never handled */
        if (o->tir == EYE_TIR_ABSORB) { h.status = EYE_ABSORBED; return h; }
        if (o->tir == EYE_TIR_MISS || bounce == EYE_MAX_BOUNCES) { h.status = EYE_MISSED; return h; }
        dir = normalize(dir - 2.0f * cosi * nf);
        org = f;
        if (!eye_roots(org, dir, c, o->r, &t1, &tf)) tf = 0.0f;
    }
}

/* ---- pigment and the drivers ------------------------------------------------------- */

/* Bilinear, periodic sample of the pigment tile (w x h RGBA floats) at a point in
 * pitches; the tile spans 1 x tile_h pitches with texel centres at (x+1/2)/w. */
inline float4 eye_pigment(__global const float4 *pig, int w, int h, float tile_h, float2 q)
{
    float fx = q.x * (float)w - 0.5f, fy = q.y / tile_h * (float)h - 0.5f;
    float x0 = floor(fx), y0 = floor(fy);
    float ax = fx - x0, ay = fy - y0;
    int i0 = (int)x0 % w, j0 = (int)y0 % h;
    i0 += i0 < 0 ? w : 0;
    j0 += j0 < 0 ? h : 0;
    int i1 = i0 + 1 == w ? 0 : i0 + 1, j1 = j0 + 1 == h ? 0 : j0 + 1;
    float4 top = mix(pig[j0 * w + i0], pig[j0 * w + i1], ax), bot = mix(pig[j1 * w + i0], pig[j1 * w + i1], ax);
    return mix(top, bot, ay);
}

/* Pigment colour seen along a traced ray; alpha 1 when it reached pigment, 0 when missed. */
inline float4 eye_shade_hit(const struct eye_hit *h, __global const float4 *pig, int pw, int ph, float tile_h,
                            float4 dot_col, float4 base_col)
{
    if (h->status == EYE_ABSORBED) return (float4)(dot_col.xyz, 1.0f);
    if (h->status == EYE_MISSED) return (float4)(base_col.xyz, 0.0f);
    return (float4)(eye_pigment(pig, pw, ph, tile_h, h->land).xyz, 1.0f);
}

/* Hemi-octahedral map: square coordinates (u,v) in [-1,1]^2 -> unit direction, z >= 0. */
inline float3 eye_octa_dir(float2 uv)
{
    float2 p = (float2)(uv.x + uv.y, uv.x - uv.y) * 0.5f;
    return normalize((float3)(p, 1.0f - fabs(p.x) - fabs(p.y)));
}

/* The lens LUT, one work-item per (direction tile, in-cell sample): global size
 * (C*C, D*D). Output: out[tile * C*C + cj*C + ci], the mean over ss x ss sub-rays
 * spread over the sample's footprint in the cell (digest §8.1). */
__kernel void eye_lut(__global float4 *out, __global const float4 *pig, int pw, int ph, struct eye_optics o,
                      int cells, int dirs, int ss, float4 dot_col, float4 base_col)
{
    int cell = get_global_id(0), tile = get_global_id(1);
    int ci = cell % cells, cj = cell / cells, ti = tile % dirs, tj = tile / dirs;
    float3 w = eye_octa_dir((float2)((2 * ti + 1) / (float)dirs - 1.0f, (2 * tj + 1) / (float)dirs - 1.0f));
    float4 acc = (float4)(0.0f);
    float inv = 1.0f / (float)(cells * ss);
    for (int sy = 0; sy < ss; sy++)
        for (int sx = 0; sx < ss; sx++) {
            float2 q = (float2)(((float)(ci * ss + sx) + 0.5f) * inv, ((float)(cj * ss + sy) + 0.5f) * inv * o.tile_h);
            struct eye_hit h = eye_trace(&o, q, -w);
            acc += eye_shade_hit(&h, pig, pw, ph, o.tile_h, dot_col, base_col);
        }
    out[tile * cells * cells + cell] = acc / (float)(ss * ss);
}

/* Raw traces for tests and benches: ray k enters at pd[k].xy with direction pd[k+n]...
 * packed as in_p[k] = (p.x, p.y, _, _), in_d[k] = (d, _). out[k] = (land, status, passes),
 * nrm[k] = (entry normal, entered). */
__kernel void eye_trace_rays(__global const float4 *in_p, __global const float4 *in_d, __global float4 *out,
                             __global float4 *nrm, struct eye_optics o)
{
    int k = get_global_id(0);
    struct eye_hit h = eye_trace(&o, in_p[k].xy, in_d[k].xyz);
    out[k] = (float4)(h.land, (float)h.status, (float)h.passes);
    nrm[k] = (float4)(h.normal, (float)h.entered);
}

/* Shading constants of the bake (eq. 5.31, G15). */
struct eye_shading {
    float4 eye;     /* object-space eye position */
    float4 light;   /* unit direction towards the light */
    float ka, kd, ks, shininess;
    float density;  /* R_t, cells per UV unit (eq. 5.1) */
    int lens_normal; /* 1: Phong with the lens normal at entry; 0: the object normal */
    int pad0, pad1;
};

/* The baked view texture (digest §8.2), one work-item per atlas texel. geo holds four
 * float4 per texel: (P, u), (N_face, v), (dP/du, mask), (dP/dv, 0), with u, v the raw
 * OBJ texture coordinates; eq. 5.1 scales them (and dP/du, dP/dv) by the density. */
__kernel void eye_bake(__global float4 *out, __global const float4 *geo, __global const float4 *pig, int pw, int ph,
                       struct eye_optics o, struct eye_shading s, float4 dot_col, float4 base_col)
{
    int k = get_global_id(0);
    float4 g0 = geo[4 * k], g1 = geo[4 * k + 1], g2 = geo[4 * k + 2], g3 = geo[4 * k + 3];
    if (g2.w == 0.0f) { out[k] = (float4)(0.0f); return; }
    float3 P = g0.xyz, N = g1.xyz, du = g2.xyz / s.density, dv = g3.xyz / s.density;
    float lu = length(du), lv = length(dv), pitch = sqrt(lu * lv);
    float3 T = du / lu, B = dv / lv, V = normalize(P - s.eye.xyz);
    /* V in cell units of the frame (D_u, D_v, N) (G1, G2: face normal for the lattice) */
    float3 d = normalize((float3)(dot(V, du) / (lu * lu), dot(V, dv) / (lv * lv), dot(V, N) / pitch));
    float a = g0.w * s.density, b = g1.w * s.density;
    float2 q = (float2)(a - floor(a), b - o.tile_h * floor(b / o.tile_h));
    float4 ct = base_col;
    float3 nl = N;
    if (d.z < -1e-4f) {
        struct eye_hit h = eye_trace(&o, q, d);
        ct = eye_shade_hit(&h, pig, pw, ph, o.tile_h, dot_col, base_col);
        if (s.lens_normal && h.entered) nl = normalize(h.normal.x * T + h.normal.y * B + h.normal.z * N);
    }
    float3 L = s.light.xyz, H = normalize(L - V);
    float diff = fmax(dot(nl, L), 0.0f), spec = pow(fmax(dot(nl, H), 0.0f), s.shininess);
    out[k] = (float4)(ct.xyz * (s.ka + s.kd * diff) + s.ks * spec, 1.0f); /* eq. 5.31 */
}
