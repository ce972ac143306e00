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
 * Each work-item traces EYE_LANES neighbouring rays (adjacent texels or table samples, so
 * their paths are alike) as the lanes of one float vector: PoCL does not vectorise the
 * divergent walks across work-items, but emits SIMD code for vector types. The host builds
 * with EYE_LANES = the device's preferred float vector width, 16 on AVX-512 (one register
 * per value, half the instructions of two float8 halves), else 8. Loops run while any lane
 * still needs them, lanes that are done are masked (select instead of if).
 *
 * The host shares struct eye_optics and the EYE_* constants through compound_eye_layout.h;
 * tests/ref/eye_ref.c is the independent double-precision reference. */

/* The optics record and its enum values come from compound_eye_layout.h, which the build
 * prepends; EYE_LANES from the build options. */
#define EYE_MAX_BOUNCES 4 /* digest §7 G8: reflect at most 4 times, then count a miss */
#define EYE_WALK_MAX 96   /* Voronoi cells walked looking for the entry lens */
#define EYE_BIG 1e30f /* "none yet" (finite: the build may assume finite math) */

#ifndef EYE_LANES
#define EYE_LANES 8
#endif
#if EYE_LANES == 16
typedef float16 fv;
typedef int16 iv; /* lane masks: -1 where true (vector comparisons), 0 elsewhere */
#define EYE_VLOAD vload16
#define EYE_VSTORE vstore16
#define EYE_FLOATS convert_float16
#define EYE_LANE_IDS ((iv)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))
#else
typedef float8 fv;
typedef int8 iv;
#define EYE_VLOAD vload8
#define EYE_VSTORE vstore8
#define EYE_FLOATS convert_float8
#define EYE_LANE_IDS ((iv)(0, 1, 2, 3, 4, 5, 6, 7))
#endif
typedef struct {
    fv x, y, z;
} v3;

struct eye_hit {
    fv lx, ly;  /* landing point on the pigment plane, pitches (lanes with EYE_LANDED) */
    v3 normal;  /* outward lens normal at the entry point ((0,0,1) where no lens was hit) */
    iv status;  /* EYE_LANDED | EYE_MISSED | EYE_ABSORBED */
    iv entered; /* mask: the ray entered a lens */
    iv passes;  /* neighbour switches taken */
};

/* ---- 3-vectors of lanes ------------------------------------------------------------ */

static v3 v3_make(fv x, fv y, fv z)
{
    v3 r = {x, y, z};
    return r;
}
static v3 v3_sub(v3 a, v3 b) { return v3_make(a.x - b.x, a.y - b.y, a.z - b.z); }
static v3 v3_mul(v3 a, fv k) { return v3_make(a.x * k, a.y * k, a.z * k); }
static fv v3_dot(v3 a, v3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
/* a + k·b */
static v3 v3_mad(v3 a, fv k, v3 b) { return v3_make(mad(k, b.x, a.x), mad(k, b.y, a.y), mad(k, b.z, a.z)); }
static v3 v3_normalize(v3 a) { return v3_mul(a, rsqrt(v3_dot(a, a))); }
static v3 v3_const(float x, float y, float z) { return v3_make((fv)x, (fv)y, (fv)z); }
/* m ? b : a, per lane */
static v3 v3_sel(v3 a, v3 b, iv m) { return v3_make(select(a.x, b.x, m), select(a.y, b.y, m), select(a.z, b.z, m)); }

static float eye_max_lane(fv v)
{
#if EYE_LANES == 16
    float8 m8 = fmax(v.lo, v.hi);
#else
    float8 m8 = v;
#endif
    float4 m4 = fmax(m8.lo, m8.hi);
    float2 m2 = fmax(m4.lo, m4.hi);
    return fmax(m2.x, m2.y);
}

/* ---- lattice ----------------------------------------------------------------------- */
/* Lattice points are o + i*(1,0) + j*e2: square o=(1/2,1/2), e2=(0,1) (cell centres, eqs.
 * 5.17-5.20 = floor+1/2, G4); hex o=(1/2,sqrt3/4), e2=(1/2,sqrt3/2) (G18), pitch 1. */

static float2 eye_e2(int lattice) { return lattice == EYE_HEX ? (float2)(0.5f, 0.5f * EYE_SQRT3) : (float2)(0.0f, 1.0f); }

/* Nearest lattice point (the Voronoi cell containing q): the lens whose cap is the top of
 * the lens layer above q. Hex: the closer of the two rectangular sub-lattices. */
static void eye_nearest(int lattice, fv qx, fv qy, fv *cx, fv *cy)
{
    if (lattice != EYE_HEX) {
        *cx = floor(qx) + 0.5f;
        *cy = floor(qy) + 0.5f;
        return;
    }
    const float h = EYE_SQRT3;
    fv ax = 0.5f + rint(qx - 0.5f), ay = 0.25f * h + h * rint((qy - 0.25f * h) / h);
    fv bx = rint(qx), by = 0.75f * h + h * rint((qy - 0.75f * h) / h);
    fv dax = qx - ax, day = qy - ay, dbx = qx - bx, dby = qy - by;
    iv pick_a = dax * dax + day * day <= dbx * dbx + dby * dby;
    *cx = select(bx, ax, pick_a);
    *cy = select(by, ay, pick_a);
}

/* Unit vectors to the Voronoi neighbours (all at distance 1 = one pitch). */
__constant float2 eye_square_walls[4] = {(float2)(1.0f, 0.0f), (float2)(0.0f, 1.0f), (float2)(-1.0f, 0.0f),
                                         (float2)(0.0f, -1.0f)};
__constant float2 eye_hex_walls[6] = {(float2)(1.0f, 0.0f), (float2)(0.5f, 0.8660254f), (float2)(-0.5f, 0.8660254f),
                                      (float2)(-1.0f, 0.0f), (float2)(-0.5f, -0.8660254f), (float2)(0.5f, -0.8660254f)};

/* Rays o + t d (d unit) against the spheres (c, r): the lanes that meet them, with the
 * two roots t1 <= t2. */
static iv eye_roots(v3 o, v3 d, v3 c, float r, fv *t1, fv *t2)
{
    v3 oc = v3_sub(o, c);
    fv b = v3_dot(oc, d), disc = b * b - (v3_dot(oc, oc) - r * r), s = sqrt(fmax(disc, 0.0f));
    *t1 = -b - s;
    *t2 = -b + s;
    return disc >= 0.0f;
}

/* ---- entry lens (digest §2.4, G3) -------------------------------------------------- */

/* Exact: walk the Voronoi cells the ray's projection crosses. Inside one cell the top of
 * the (equal, equally deep) lens layer is that cell's sphere, so the first root found
 * within the cell's stretch of the ray is the first lens hit. The walk ends at depth r,
 * where the thesis stops looking (§2.4): below it the ray goes on unrefracted. Returns
 * the lanes that entered a lens, with its centre (cx, cy) and the entry distance t. */
static iv eye_enter_exact(const struct eye_optics *o, fv px, fv py, v3 d, iv live, fv *cx, fv *cy, fv *t)
{
    const float r = o->r;
    const int hex = o->lattice == EYE_HEX, walls = hex ? 6 : 4;
    const v3 p = v3_make(px, py, (fv)0.0f);
    fv tmax = r / -d.z, t_in = 0.0f, wx, wy; /* tmax: the ray is at depth r */
    eye_nearest(o->lattice, px, py, &wx, &wy);
    iv search = live, hit = 0;
    for (int k = 0; k < EYE_WALK_MAX && any(search); k++) {
        fv t_exit = EYE_BIG, sx = 0.0f, sy = 0.0f, t1, t2;
        for (int e = 0; e < walls; e++) { /* the cell's walls: bisectors to its Voronoi neighbours */
            float2 v = hex ? eye_hex_walls[e] : eye_square_walls[e];
            fv den = d.x * v.x + d.y * v.y;
            iv toward = den > 1e-9f;
            fv te = ((wx - px) * v.x + (wy - py) * v.y + 0.5f) / select((fv)1.0f, den, toward);
            iv nearer = toward & (te < t_exit);
            t_exit = select(t_exit, te, nearer);
            sx = select(sx, (fv)v.x, nearer);
            sy = select(sy, (fv)v.y, nearer);
        }
        iv found = search & eye_roots(p, d, v3_make(wx, wy, (fv)(-r)), r, &t1, &t2) & (t2 >= t_in) & (t1 <= t_exit);
        *cx = select(*cx, wx, found);
        *cy = select(*cy, wy, found);
        *t = select(*t, fmax(t1, 0.0f), found);
        hit |= found;
        t_in = t_exit;
        search &= ~found & (t_in <= tmax);
        eye_nearest(o->lattice, wx + sx, wy + sy, &wx, &wy); /* snap, so rounding never drifts off-lattice */
    }
    return hit & (*t <= tmax);
}

/* The thesis's slice planes (eqs. 5.23-5.27): at depths h = 0, r/s, ..., r take the lens
 * whose cell contains the ray's point at depth h lifted back to the surface; the first
 * one the ray meets is the entry lens. */
static iv eye_enter_slices(const struct eye_optics *o, fv px, fv py, v3 d, iv live, fv *cx, fv *cy, fv *t)
{
    const float r = o->r;
    const v3 p = v3_make(px, py, (fv)0.0f);
    iv search = live, hit = 0;
    for (int s = 0; s <= o->slices && any(search); s++) {
        fv ts = r * (float)s / (float)o->slices / -d.z, wx, wy, t1, t2;
        eye_nearest(o->lattice, px + d.x * ts, py + d.y * ts, &wx, &wy);
        iv found = search & eye_roots(p, d, v3_make(wx, wy, (fv)(-r)), r, &t1, &t2) & (t2 >= 0.0f);
        *cx = select(*cx, wx, found);
        *cy = select(*cy, wy, found);
        *t = select(*t, fmax(t1, 0.0f), found);
        hit |= found;
        search &= ~found;
    }
    return hit;
}

/* ---- internal pass (digest §2.6, G5, G6) ------------------------------------------- */

/* Lanes where the thesis's sign of x (+1 when x > 0, else -1) equals i. */
static iv eye_sign_is(int i, fv x) { return i == 1 ? x > 0.0f : i == -1 ? x <= 0.0f : (iv)0; }

/* thesis4 (Fig. 5.10): only the three neighbours of the region R_dir points into; v is
 * the candidate's offset from the current lens. */
static iv eye_thesis4(int lattice, float2 v, v3 dir)
{
    if (lattice == EYE_HEX) return dot(v, v) < 1.5f ? v.x * dir.x + v.y * dir.y > 0.0f : (iv)0;
    int ix = (int)rint(v.x), iy = (int)rint(v.y);
    iv along_x = abs(iy) <= 1 ? eye_sign_is(ix, dir.x) : (iv)0, along_y = abs(ix) <= 1 ? eye_sign_is(iy, dir.y) : (iv)0;
    return select(along_y, along_x, fabs(dir.x) >= fabs(dir.y));
}

/* From the far root tf of lens c on the ray (org, dir): while the far point f lies inside
 * other lenses, move to the one whose own far root is farthest (G5), on the same unbent
 * ray (G6); each move counts one pass against l. A lens contains f when its centre is
 * within rho (the radius of the lenses' section at f's height: all centres lie at
 * z = -r) of f horizontally, so the candidates are the lattice offsets from c in the box
 * that holds every lane's disc (f - c, rho); the lanes are neighbouring rays, so the box
 * is hardly larger than one disc. */
static fv eye_inner_pass(const struct eye_optics *o, v3 org, v3 dir, fv *cx, fv *cy, fv tf, iv *passes, iv live)
{
    const float r = o->r, r2 = r * r;
    const float2 e2 = eye_e2(o->lattice);
    iv go = live & (*passes < o->max_passes);
    while (any(go)) {
        v3 f = v3_mad(org, tf, dir);
        fv hx = f.x - *cx, hy = f.y - *cy, dz = f.z + r, rho2 = r2 - dz * dz, rho = sqrt(fmax(rho2, 0.0f));
        fv qd0 = hx * dir.x + hy * dir.y + dz * dir.z; /* (f - c).dir */
        float x0 = -eye_max_lane(select((fv)-EYE_BIG, rho - hx, go)), x1 = eye_max_lane(select((fv)-EYE_BIG, hx + rho, go));
        float y0 = -eye_max_lane(select((fv)-EYE_BIG, rho - hy, go)), y1 = eye_max_lane(select((fv)-EYE_BIG, hy + rho, go));
        fv best = tf * 1e-6f + 1e-6f, bx = 0.0f, by = 0.0f; /* the far root must gain this much */
        iv moved = 0;
        for (int j = (int)ceil(fmax(y0, -2.0f * r) / e2.y); j <= (int)floor(fmin(y1, 2.0f * r) / e2.y); j++) {
            float y = (float)j * e2.y, xj = (float)j * e2.x;
            for (int i = (int)ceil(fmax(x0, -2.0f * r) - xj); i <= (int)floor(fmin(x1, 2.0f * r) - xj); i++) {
                if (i == 0 && j == 0) continue; /* the current lens itself */
                float2 v = (float2)((float)i + xj, y);
                fv qx = hx - v.x, qy = hy - v.y, h2 = qx * qx + qy * qy;
                fv qd = qd0 - (v.x * dir.x + v.y * dir.y);
                fv t2 = sqrt(fmax(qd * qd + rho2 - h2, 0.0f)) - qd; /* far root, measured from f */
                iv better = go & (h2 < rho2) & (t2 > best);
                if (o->select == EYE_SELECT_THESIS4) better &= eye_thesis4(o->lattice, v, dir);
                best = select(best, t2, better);
                bx = select(bx, (fv)v.x, better);
                by = select(by, (fv)v.y, better);
                moved |= better;
            }
        }
        fv nx, ny;
        eye_nearest(o->lattice, *cx + bx, *cy + by, &nx, &ny); /* snap to the lattice */
        *cx = select(*cx, nx, moved);
        *cy = select(*cy, ny, moved);
        tf = select(tf, tf + best, moved);
        *passes = select(*passes, *passes + 1, moved);
        go = moved & (*passes < o->max_passes);
    }
    return tf;
}

/* ---- the core ---------------------------------------------------------------------- */

/* Lanes `live` inside their lens (c, r) on the ray (org, dir): internal pass, then refract
 * out and land, or total internal reflection by the TIR policy (G8). */
static void eye_exit(const struct eye_optics *o, v3 org, v3 dir, fv cx, fv cy, iv live, struct eye_hit *h)
{
    const float r = o->r, n = o->n;
    fv t1, tf;
    iv meets = eye_roots(org, dir, v3_make(cx, cy, (fv)(-r)), r, &t1, &tf);
    tf = select((fv)0.0f, tf, meets);
    for (int bounce = 0; any(live); bounce++) {
        tf = eye_inner_pass(o, org, dir, &cx, &cy, tf, &h->passes, live);
        v3 c = v3_make(cx, cy, (fv)(-r)), f = v3_mad(org, tf, dir), nf = v3_mul(v3_sub(f, c), (fv)(1.0f / r));
        fv cosi = v3_dot(dir, nf), k = 1.0f - n * n * (1.0f - cosi * cosi);
        iv out = live & (k >= 0.0f);
        /* refract out: GLSL refract(dir, -nf, n) */
        v3 ro = v3_sub(v3_mul(dir, (fv)n), v3_mul(nf, n * cosi - sqrt(fmax(k, 0.0f))));
        iv up = ro.z >= -1e-6f, land = out & ~up;
        fv tl = (-o->plane - f.z) / select((fv)-1.0f, ro.z, land);
        h->status = select(h->status, (iv)EYE_MISSED, out & up); /* G9 */
        h->lx = select(h->lx, f.x + ro.x * tl, land);
        h->ly = select(h->ly, f.y + ro.y * tl, land);
        /* G8: total internal reflection, which the thesis never handled */
        iv tir = live & ~out;
        if (o->tir != EYE_TIR_REFLECT || bounce == EYE_MAX_BOUNCES) {
            h->status = select(h->status, (iv)(o->tir == EYE_TIR_ABSORB ? EYE_ABSORBED : EYE_MISSED), tir);
            return;
        }
        dir = v3_sel(dir, v3_normalize(v3_mad(dir, -2.0f * cosi, nf)), tir);
        org = v3_sel(org, f, tir);
        meets = eye_roots(org, dir, c, r, &t1, &tf);
        tf = select((fv)0.0f, tf, meets);
        live = tir;
    }
}

/* d: unit view directions (towards the surface, d.z < 0); (px, py): in-cell entry
 * points; only the `live` lanes are traced. */
static struct eye_hit eye_trace(const struct eye_optics *o, fv px, fv py, v3 d, iv live)
{
    struct eye_hit h;
    fv tp = o->plane / -d.z, cx = 0.0f, cy = 0.0f, t = 0.0f;
    h.lx = px + d.x * tp; /* §2.4: no lens down to depth r, the ray goes on unrefracted */
    h.ly = py + d.y * tp;
    h.normal = v3_const(0.0f, 0.0f, 1.0f);
    h.status = EYE_LANDED;
    h.entered = 0;
    h.passes = 0;
    iv in = o->search == EYE_SEARCH_SLICES ? eye_enter_slices(o, px, py, d, live, &cx, &cy, &t)
                                           : eye_enter_exact(o, px, py, d, live, &cx, &cy, &t);
    if (!any(in)) return h;
    h.entered = in;
    v3 org = v3_mad(v3_make(px, py, (fv)0.0f), t, d);
    v3 nn = v3_mul(v3_sub(org, v3_make(cx, cy, (fv)(-o->r))), (fv)(1.0f / o->r)); /* eq. 5.28 */
    h.normal = v3_sel(h.normal, nn, in);
    float eta = 1.0f / o->n;
    fv ci = -v3_dot(nn, d);
    v3 dir = v3_normalize(v3_mad(v3_mul(d, (fv)eta), eta * ci - sqrt(fmax(0.0f, 1.0f - eta * eta * (1.0f - ci * ci))), nn));
    eye_exit(o, org, dir, cx, cy, in, &h);
    return h;
}

/* ---- pigment and the drivers ------------------------------------------------------- */

struct eye_rgba {
    fv r, g, b, a;
};

/* Bilinear, periodic sample of the pigment tile (w x h RGBA floats) at a point in
 * pitches; the tile spans 1 x tile_h pitches with texel centres at (x+1/2)/w. */
static float4 eye_pigment(__global const float4 *pig, int w, int h, float tile_h, float2 q)
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

/* Pigment colour seen along the lanes' rays; alpha 1 where they reached pigment, 0 where
 * they missed. The tile is read lane by lane (a gather). */
static struct eye_rgba eye_shade(const struct eye_hit *h, __global const float4 *pig, int pw, int ph, float tile_h,
                                 float4 dot_col, float4 base_col)
{
    float lx[EYE_LANES], ly[EYE_LANES], cr[EYE_LANES], cg[EYE_LANES], cb[EYE_LANES];
    int st[EYE_LANES];
    EYE_VSTORE(h->lx, 0, lx);
    EYE_VSTORE(h->ly, 0, ly);
    EYE_VSTORE(h->status, 0, st);
    for (int i = 0; i < EYE_LANES; i++) {
        float4 c = st[i] == EYE_ABSORBED ? dot_col
                   : st[i] == EYE_MISSED ? base_col
                                         : eye_pigment(pig, pw, ph, tile_h, (float2)(lx[i], ly[i]));
        cr[i] = c.x;
        cg[i] = c.y;
        cb[i] = c.z;
    }
    struct eye_rgba c = {EYE_VLOAD(0, cr), EYE_VLOAD(0, cg), EYE_VLOAD(0, cb), select((fv)1.0f, (fv)0.0f, h->status == EYE_MISSED)};
    return c;
}

/* Writes lane i as out[k0 + i] = (x, y, z, w) for k0 + i < n. */
static void eye_store(__global float4 *out, int k0, int n, fv x, fv y, fv z, fv w)
{
    float a[EYE_LANES], b[EYE_LANES], c[EYE_LANES], e[EYE_LANES];
    EYE_VSTORE(x, 0, a);
    EYE_VSTORE(y, 0, b);
    EYE_VSTORE(z, 0, c);
    EYE_VSTORE(w, 0, e);
    for (int i = 0; i < EYE_LANES && k0 + i < n; i++) out[k0 + i] = (float4)(a[i], b[i], c[i], e[i]);
}

/* The rays of work-item slots k0 ... k0 + EYE_LANES - 1 in the host's order (eye_order.h), into
 * ray[]: their index vector. */
static iv eye_rays(__global const int *order, int *ray)
{
    iv k = EYE_VLOAD(0, order + (int)get_global_id(0) * EYE_LANES);
    EYE_VSTORE(k, 0, ray);
    return k;
}

/* Writes lane l as out[ray[l]] = (x, y, z, w) and cost[ray[l]] = c (capped at EYE_COST_MAX)
 * for ray[l] < n. */
static void eye_store_rays(__global float4 *out, __global uchar *cost, const int *ray, int n, fv x, fv y, fv z, fv w,
                           iv c)
{
    float a[EYE_LANES], b[EYE_LANES], d[EYE_LANES], e[EYE_LANES];
    int k[EYE_LANES];
    EYE_VSTORE(x, 0, a);
    EYE_VSTORE(y, 0, b);
    EYE_VSTORE(z, 0, d);
    EYE_VSTORE(w, 0, e);
    EYE_VSTORE(min(c, (iv)EYE_COST_MAX), 0, k);
    for (int l = 0; l < EYE_LANES; l++)
        if (ray[l] < n) {
            out[ray[l]] = (float4)(a[l], b[l], d[l], e[l]);
            cost[ray[l]] = (uchar)k[l];
        }
}

/* What tracing a ray cost (EYE_COST_*): the lenses it passed through. */
static iv eye_cost(const struct eye_hit *h)
{
    return select((iv)EYE_COST_TRACED, EYE_COST_ENTERED + h->passes, h->entered);
}

/* Lanes i of in[k0 + i] (the last element for k0 + i >= n). */
static void eye_load(__global const float4 *in, int k0, int n, fv *x, fv *y, fv *z)
{
    float a[EYE_LANES], b[EYE_LANES], c[EYE_LANES];
    for (int i = 0; i < EYE_LANES; i++) {
        float4 v = in[min(k0 + i, n - 1)];
        a[i] = v.x;
        b[i] = v.y;
        c[i] = v.z;
    }
    *x = EYE_VLOAD(0, a);
    *y = EYE_VLOAD(0, b);
    *z = EYE_VLOAD(0, c);
}

static iv eye_lane_index(void) { return (int)get_global_id(0) * EYE_LANES + EYE_LANE_IDS; }

/* Hemi-octahedral map: square coordinates (u,v) in [-1,1]^2 -> unit direction, z >= 0. */
static v3 eye_octa_dir(fv u, fv v)
{
    fv px = (u + v) * 0.5f, py = (u - v) * 0.5f;
    return v3_normalize(v3_make(px, py, 1.0f - fabs(px) - fabs(py)));
}

/* The lens LUT, EYE_LANES samples per work-item over the flat index k = slot * C*C + cj*C + ci of
 * the direction tiles to trace, tile tiles[slot] (global size ceil(ntiles*C*C / EYE_LANES); the
 * host copies the others by symmetry, server/effects/eye_lut.h), sample order[s] in work-item
 * slot s (eye_order.h). Output: out[k], the mean over ss x ss sub-rays spread over the
 * sample's footprint in the cell (digest §8.1), and cost[k], the sub-rays' summed cost. */
__kernel void eye_lut(__global float4 *out, __global uchar *cost, __global const int *order, __global const float4 *pig,
                      int pw, int ph, struct eye_optics o, __global const int *tiles, int ntiles, int cells, int dirs,
                      int ss, float4 dot_col, float4 base_col)
{
    const int per = cells * cells, total = per * ntiles;
    int ray[EYE_LANES];
    iv k = eye_rays(order, ray), live = k < total, c = 0;
    k = min(k, total - 1);
    int slot[EYE_LANES], t[EYE_LANES];
    EYE_VSTORE(k / per, 0, slot);
    for (int i = 0; i < EYE_LANES; i++) t[i] = tiles[slot[i]];
    iv cell = k % per, tile = EYE_VLOAD(0, t);
    iv ci = cell % cells, cj = cell / cells, ti = tile % dirs, tj = tile / dirs;
    v3 w = eye_octa_dir(EYE_FLOATS(2 * ti + 1) / (float)dirs - 1.0f, EYE_FLOATS(2 * tj + 1) / (float)dirs - 1.0f);
    v3 d = v3_mul(w, (fv)-1.0f);
    struct eye_rgba acc = {(fv)0.0f, (fv)0.0f, (fv)0.0f, (fv)0.0f};
    float inv = 1.0f / (float)(cells * ss);
    for (int sy = 0; sy < ss; sy++)
        for (int sx = 0; sx < ss; sx++) {
            fv qx = (EYE_FLOATS(ci * ss + sx) + 0.5f) * inv, qy = (EYE_FLOATS(cj * ss + sy) + 0.5f) * inv * o.tile_h;
            struct eye_hit h = eye_trace(&o, qx, qy, d, live);
            struct eye_rgba col = eye_shade(&h, pig, pw, ph, o.tile_h, dot_col, base_col);
            acc.r += col.r;
            acc.g += col.g;
            acc.b += col.b;
            acc.a += col.a;
            c += eye_cost(&h);
        }
    float m = 1.0f / (float)(ss * ss);
    eye_store_rays(out, cost, ray, total, acc.r * m, acc.g * m, acc.b * m, acc.a * m, c);
}

/* Raw traces for tests and benches, EYE_LANES rays per work-item (global size ceil(n / EYE_LANES)): ray k
 * enters at in_p[k] = (p.x, p.y, _, _) with direction in_d[k] = (d, _). out[k] = (land,
 * status, passes), nrm[k] = (entry normal, entered). */
__kernel void eye_trace_rays(__global const float4 *in_p, __global const float4 *in_d, __global float4 *out,
                             __global float4 *nrm, struct eye_optics o, int n)
{
    int k0 = (int)get_global_id(0) * EYE_LANES;
    fv px, py, pz;
    v3 d;
    eye_load(in_p, k0, n, &px, &py, &pz);
    eye_load(in_d, k0, n, &d.x, &d.y, &d.z);
    struct eye_hit h = eye_trace(&o, px, py, d, eye_lane_index() < n);
    eye_store(out, k0, n, h.lx, h.ly, EYE_FLOATS(h.status), EYE_FLOATS(h.passes));
    eye_store(nrm, k0, n, h.normal.x, h.normal.y, h.normal.z, EYE_FLOATS(h.entered & 1));
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

/* The bake's geometry in its texel order: slot k of 16 planes of npad floats (plane i at
 * planes[i * npad + k]) from texel order[k] of the atlas (16 floats a texel, eye_model.h), so
 * that eye_bake loads a field of its lanes as one vector. One work-item a slot. */
__kernel void eye_bake_gather(__global float *planes, __global const float16 *geo, __global const int *order, int npad)
{
    const int k = (int)get_global_id(0);
    float g[16];
    if (k >= npad) return;
    vstore16(geo[order[k]], 0, g);
    for (int i = 0; i < 16; i++) planes[i * npad + k] = g[i];
}

/* The baked view texture (digest §8.2), EYE_LANES texels per work-item (npad / EYE_LANES of
 * them, which may run a range at a time). Slot k0 + l traces texel order[k0 + l] (eye_order.h; the
 * texels from n on are padding) and writes its colour and cost there. geo holds the slots' geometry
 * (eye_bake_gather), 16 planes of npad floats: P, u, N_face, v, dP/du, mask, dP/dv, 0, with u,
 * v the raw OBJ texture coordinates; eq. 5.1 scales them (and dP/du, dP/dv) by the density. */
__kernel void eye_bake(__global float4 *out, __global uchar *cost, __global const float *geo,
                       __global const int *order, __global const float4 *pig, int pw, int ph, struct eye_optics o,
                       struct eye_shading s, float4 dot_col, float4 base_col, int n, int npad)
{
    const int k0 = (int)get_global_id(0) * EYE_LANES;
    int texel[EYE_LANES];
    eye_rays(order, texel);
#define EYE_GEO(i) EYE_VLOAD(0, geo + (i) * npad + k0)
    iv covered = EYE_GEO(11) != 0.0f;
    if (!any(covered)) {
        eye_store_rays(out, cost, texel, n, (fv)0.0f, (fv)0.0f, (fv)0.0f, (fv)0.0f, (iv)EYE_COST_BARE);
        return;
    }
    const v3 up = v3_const(0.0f, 0.0f, 1.0f), eye = v3_const(s.eye.x, s.eye.y, s.eye.z);
    v3 P = v3_make(EYE_GEO(0), EYE_GEO(1), EYE_GEO(2)), N = v3_sel(up, v3_make(EYE_GEO(4), EYE_GEO(5), EYE_GEO(6)), covered);
    v3 du = v3_sel(v3_const(1.0f, 0.0f, 0.0f), v3_mul(v3_make(EYE_GEO(8), EYE_GEO(9), EYE_GEO(10)), (fv)(1.0f / s.density)), covered);
    v3 dv = v3_sel(v3_const(0.0f, 1.0f, 0.0f), v3_mul(v3_make(EYE_GEO(12), EYE_GEO(13), EYE_GEO(14)), (fv)(1.0f / s.density)), covered);
    fv a = EYE_GEO(3) * s.density, b = EYE_GEO(7) * s.density;
#undef EYE_GEO
    fv lu = sqrt(v3_dot(du, du)), lv = sqrt(v3_dot(dv, dv)), pitch = sqrt(lu * lv);
    v3 T = v3_mul(du, 1.0f / lu), B = v3_mul(dv, 1.0f / lv), V = v3_normalize(v3_sub(P, eye));
    /* V in cell units of the frame (D_u, D_v, N) (G1, G2: face normal for the lattice) */
    v3 d = v3_normalize(v3_make(v3_dot(V, du) / (lu * lu), v3_dot(V, dv) / (lv * lv), v3_dot(V, N) / pitch));
    fv qx = a - floor(a), qy = b - o.tile_h * floor(b / o.tile_h);
    iv traced = covered & (d.z < -1e-4f);
    struct eye_hit h = eye_trace(&o, select((fv)0.0f, qx, traced), select((fv)0.0f, qy, traced),
                                 v3_sel(v3_const(0.0f, 0.0f, -1.0f), d, traced), traced);
    struct eye_rgba ct = eye_shade(&h, pig, pw, ph, o.tile_h, dot_col, base_col);
    v3 nl = N;
    if (s.lens_normal)
        nl = v3_sel(N, v3_normalize(v3_mad(v3_mad(v3_mul(T, h.normal.x), h.normal.y, B), h.normal.z, N)), h.entered);
    const v3 L = v3_const(s.light.x, s.light.y, s.light.z);
    v3 H = v3_normalize(v3_sub(L, V));
    /* spec = pow(max(nl.H, 0), shininess) as exp2(shininess log2(.)): PoCL's pow runs lane
     * by lane, its exp2 and log2 on the vector (1e-30 for 0: its 2^-100s is 0 in float) */
    fv diff = fmax(v3_dot(nl, L), 0.0f), spec = exp2(s.shininess * log2(fmax(v3_dot(nl, H), 1e-30f)));
    fv lit = s.ka + s.kd * diff, gloss = s.ks * spec; /* eq. 5.31 */
    fv cr = select((fv)base_col.x, ct.r, traced), cg = select((fv)base_col.y, ct.g, traced);
    fv cb = select((fv)base_col.z, ct.b, traced), zero = 0.0f;
    iv c = select(select(eye_cost(&h), (iv)EYE_COST_COVERED, ~traced), (iv)EYE_COST_BARE, ~covered);
    eye_store_rays(out, cost, texel, n, select(zero, cr * lit + gloss, covered), select(zero, cg * lit + gloss, covered),
                   select(zero, cb * lit + gloss, covered), select(zero, (fv)1.0f, covered), c);
}
