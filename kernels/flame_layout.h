/* flame_layout.h — what server/effects/flame.c and kernels/flame.cl must agree on: the indices
 * of the parameter array (one __constant float array, FP_COUNT floats, packed by flame_params.c's
 * flame_params_pack), the particle flag bits and the error bits a step reports. Valid C and
 * OpenCL C: flame.c (and flame.h's public flag enum) include it, and the build
 * (tools/embed_kernels.sh) prepends it to flame.cl, so the layout exists once. */
#ifndef FLAME_LAYOUT_H
#define FLAME_LAYOUT_H

#define FP_H 0
#define FP_H2 1
#define FP_INV_CELL 2
#define FP_MASS 3
#define FP_POLY6 4      /* m * 315/(64 pi h^9) */
#define FP_SPIKY 5      /* 45/(pi h^6): spiky gradient and viscosity Laplacian magnitude */
#define FP_GPOLY6 6     /* m * 945/(32 pi h^9): colour-field normal */
#define FP_KSTIFF 7
#define FP_RHO0 8
#define FP_KVISC 9
#define FP_KBUO 10
#define FP_UP 11        /* 11..13 */
#define FP_WIND 14      /* 14..16 */
#define FP_TAMB 17
#define FP_TIGN 18
#define FP_KRS 19
#define FP_KCF 20
#define FP_KPT 21
#define FP_KH 22
#define FP_KF 23
#define FP_OMEGA 24
#define FP_KCOOL 25
#define FP_FEPS 26
#define FP_DT 27
#define FP_DIAM 28
#define FP_VMAX 29
#define FP_SYMMETRIC 30 /* 1: Mueller's symmetric pressure form (§9 #3) */
#define FP_LITERAL 31   /* 1: diffusion as printed (§9 #4 literal mode) */
#define FP_NBR_INS 32   /* insertion neighbour threshold (§9 #8) */
#define FP_SEED 33
#define FP_INV_CELLX 34 /* cells are c/K wide along x (K = FL_XCELLS), c = h / FL_CELLS_PER_H along y and z */
#define FP_WINDV 35     /* 35..37: wind_velocity */
#define FP_DRAG 38      /* 1 - exp(-wind_drag dt) */
#define FP_COUNT 39

/* Particle flags: the type in bits 0-1, then the flame bit (digest §9 #12). */
#define FL_GAS 0u
#define FL_SOURCE 1u   /* burning solid: fixed, holds T_init/F_init (digest §2.13) */
#define FL_OBSTACLE 2u /* non-burning solid moved kinematically (digest §9 #16) */
#define FL_TYPE 3u     /* mask of the type bits */
#define FL_FLAME 4u    /* T > T_ign and F > fuel_eps */

/* Bits of the error flag a step sets (read back after every frame). */
#define FL_ERR_NAN 1   /* a non-finite position, velocity, temperature or fuel */
#define FL_ERR_SPEED 2 /* a speed above FP_VMAX: a runaway */

/* The device scan of the wide passes (flame.cl's fl_scan_*): work-group size, elements per work item. */
#define FL_SCAN_WG 256
#define FL_SCAN_E 8
#define FL_SCAN_TILE (FL_SCAN_WG * FL_SCAN_E) /* elements a work-group scans */

#endif
