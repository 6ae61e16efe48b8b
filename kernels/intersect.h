#line 2 "intersect.h"
/* Ray-triangle intersection that no ray leaks through (Woop, Benthin and Wald 2013,
 * "Watertight Ray/Triangle Intersection"), and ray origins that never re-hit their own surface
 * at any scene scale (Waechter and Binder 2019, "A Fast and Robust Method for Avoiding
 * Self-Intersection", Ray Tracing Gems ch. 6). */
#ifndef INVRENDER_INTERSECT_H
#define INVRENDER_INTERSECT_H

#if defined(cl_khr_fp64)
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#define WATERTIGHT_FP64 1
#endif

typedef struct {
    float3 o, d;
    float3 inv_d;   /* 1 / d, zero components replaced by a tiny value: no 0 * inf in box tests */
    int kz;         /* axis of largest |d|: the shear frame rotates it to z */
    float3 shear;   /* (Sx, Sy, Sz) of Woop et al. */
} Ray;

/* Rotate so that component kz comes last; a cyclic rotation keeps the handedness, so the
 * winding swap of the paper is not needed (we are two-sided anyway). */
inline float3 rotate_to_z(float3 v, int kz)
{
    return kz == 2 ? v : (kz == 0 ? v.yzx : v.zxy);
}

/* |v| and the sign bits of v by masking: the same bits as fabs and copysign, which PoCL calls
 * out of line (once per ray, on every bounce). */
inline float3 abs3(float3 v) { return as_float3(as_int3(v) & (int3)(0x7fffffff)); }

inline Ray make_ray(float3 o, float3 d)
{
    Ray r;
    r.o = o;
    r.d = d;
    float3 ad = abs3(d);
    r.kz = (ad.x > ad.y) ? (ad.x > ad.z ? 0 : 2) : (ad.y > ad.z ? 1 : 2);
    float3 dr = rotate_to_z(d, r.kz);
    r.shear = (float3)(dr.x / dr.z, dr.y / dr.z, 1.0f / dr.z);
    const float tiny = 1e-20f;
    float3 signed_tiny = as_float3(as_int3((float3)(tiny)) | (as_int3(d) & (int3)(INT_MIN)));
    r.inv_d = 1.0f / (ad < tiny ? signed_tiny : d);
    return r;
}

#ifdef WATERTIGHT_FP64
/* The edge functions of the paper in double, used only when a float edge function is exactly
 * zero (the ray passes through an edge or vertex as seen in float). */
inline void edge_functions_fp64(float3 a, float3 b, float3 c, float* U, float* V, float* W)
{
    *U = (float)((double)c.x * (double)b.y - (double)c.y * (double)b.x);
    *V = (float)((double)a.x * (double)c.y - (double)a.y * (double)c.x);
    *W = (float)((double)b.x * (double)a.y - (double)b.y * (double)a.x);
}
#endif

/* Returns 1 and sets *t, *b1, *b2 (barycentrics of v1, v2) if the ray hits the triangle at
 * 0 < t < tmax. Both sides count. */
inline int intersect_triangle(const Ray* r, float3 v0, float3 v1, float3 v2, float tmax,
                              float* t, float* b1, float* b2)
{
/* Watertightness needs an edge function shared by two triangles to come out as exact negatives
 * of each other; a fused multiply-add in a*b - c*d rounds the two orders differently and lets
 * rays through shared edges (measured: 4 of 392 rays through edges of a flat grid). */
#pragma OPENCL FP_CONTRACT OFF
    float3 a = rotate_to_z(v0 - r->o, r->kz);
    float3 b = rotate_to_z(v1 - r->o, r->kz);
    float3 c = rotate_to_z(v2 - r->o, r->kz);
    const float3 S = r->shear;
    float3 as = (float3)(a.x - S.x * a.z, a.y - S.y * a.z, S.z * a.z);
    float3 bs = (float3)(b.x - S.x * b.z, b.y - S.y * b.z, S.z * b.z);
    float3 cs = (float3)(c.x - S.x * c.z, c.y - S.y * c.z, S.z * c.z);
    float U = cs.x * bs.y - cs.y * bs.x;
    float V = as.x * cs.y - as.y * cs.x;
    float W = bs.x * as.y - bs.y * as.x;
#ifdef WATERTIGHT_FP64
    if (U == 0.0f || V == 0.0f || W == 0.0f)
        edge_functions_fp64(as, bs, cs, &U, &V, &W);
#endif
    if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f))
        return 0;
    float det = U + V + W;
    if (det == 0.0f)
        return 0;
    float T = U * as.z + V * bs.z + W * cs.z;
    /* Compare T against [0, tmax det] with det's sign folded in, no division on a miss. */
    float sdet = fabs(det);
    float sT = det < 0.0f ? -T : T;
    if (sT <= 0.0f || sT >= tmax * sdet)
        return 0;
    float inv = 1.0f / det;
    *t = T * inv;
    *b1 = V * inv;
    *b2 = W * inv;
    return 1;
}

/* Move a surface point off its surface along the geometric normal, on the side the new ray
 * leaves towards: a fixed number of float ulps far from the origin (scale-independent, from
 * centimetres to kilometres), a fixed distance near it where ulps are tiny. */
inline float3 offset_ray_origin(float3 p, float3 n)
{
    const float origin = 1.0f / 32.0f, float_scale = 1.0f / 65536.0f, int_scale = 256.0f;
    int3 of_i = convert_int3(int_scale * n);
    float3 p_i = as_float3(as_int3(p) + select(of_i, -of_i, as_int3(p) < 0));
    return select(p_i, p + float_scale * n, fabs(p) < origin);
}

#endif
