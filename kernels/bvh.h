#line 2 "bvh.h"
/* Traversal of the 8-wide BVH built on the host (workflow/invrender/render/bvh.py).
 * One ray tests eight child boxes at once with float8: on CPUs (PoCL) that is the SIMD that
 * pays, since divergent rays are not vectorised across work-items; on GPUs it is eight
 * independent slab tests per work-item. Node layout: bounds rows (min x, min y, min z, max x,
 * max y, max z) x 8 lanes; children rows (child node, or a leaf's block in bvh_leaves, count),
 * count 0 = internal node, 1..8 = leaf, -1 = empty lane (whose box is +inf..-inf and never hit).
 * A leaf block holds its triangles as 8 lanes too (intersect_leaf). The emitter BVH (lights.h)
 * has the same nodes, but a leaf lane there holds its first slot in em_v. */
#ifndef INVRENDER_BVH_H
#define INVRENDER_BVH_H

#include "common.h"
#include "scene_data.h"
#include "intersect.h"

#define BVH_STACK_SIZE 96

typedef struct {
    float t;      /* RAY_TMAX on a miss */
    int slot;     /* leaf slot of the triangle hit, -1 on a miss */
    float b1, b2; /* barycentrics of vertices 1 and 2 */
#ifdef BVH_STATS
    int nodes, tris; /* nodes and triangles visited (kernels/traversal.cl) */
#endif
} Hit;

/* Entry distances of the eight lanes; lanes missed get +inf. Near and far planes are chosen by
 * the sign of the direction, not by min/max, so empty lanes (+inf..-inf) are always missed.
 * The far distance is widened by 2 gamma(3) (Ize 2013) so float rounding never drops a box the
 * ray touches. Comparisons with ?: rather than fmin/fmax/select: PoCL calls those out of line. */
inline float8 lane_entry(global const float8* b, const Ray* r, int3 near, float tmax)
{
    float8 tnx = (b[near.x] - r->o.x) * r->inv_d.x;
    float8 tny = (b[near.y] - r->o.y) * r->inv_d.y;
    float8 tnz = (b[near.z] - r->o.z) * r->inv_d.z;
    float8 tfx = (b[3 - near.x] - r->o.x) * r->inv_d.x;
    float8 tfy = (b[5 - near.y] - r->o.y) * r->inv_d.y;
    float8 tfz = (b[7 - near.z] - r->o.z) * r->inv_d.z;
    float8 tnear = tnx > tny ? tnx : tny;
    tnear = tnear > tnz ? tnear : tnz;
    tnear = tnear > 0.0f ? tnear : (float8)(0.0f);
    float8 tfar = tfx < tfy ? tfx : tfy;
    tfar = tfar < tfz ? tfar : tfz;
    tfar = (tfar < tmax ? tfar : (float8)(tmax)) * 1.0000004f;
    return tnear <= tfar ? tnear : (float8)(INFINITY);
}

/* Rows of the near planes: min (0, 1, 2) where the direction is positive, max (3, 4, 5) else;
 * the far plane of axis k is then row 2 k + 3 - near. */
inline int3 near_rows(const Ray* r)
{
    return (int3)(r->inv_d.x < 0.0f ? 3 : 0, r->inv_d.y < 0.0f ? 4 : 1, r->inv_d.z < 0.0f ? 5 : 2);
}

inline float8 bvh_lane_entry(global const float8* bounds, int node, const Ray* r, float tmax)
{
    return lane_entry(bounds + 6 * node, r, near_rows(r), tmax);
}

/* The bits of the lanes where a comparison result (-1 / 0) is true, or-ed together. */
inline uint lane_mask_bits(int8 m, int8 bit)
{
    int8 bits = m & bit;
    int4 a = bits.lo | bits.hi;
    int2 b = a.lo | a.hi;
    return (uint)(b.x | b.y);
}

/* Bit i set where lane i of a comparison result is true. */
inline uint lane_mask(int8 m) { return lane_mask_bits(m, (int8)(1, 2, 4, 8, 16, 32, 64, 128)); }

/* Index of the lowest set bit of a nonzero mask: the exponent of the float it converts to,
 * exactly (a power of two), where OpenCL 1.2 has no ctz and PoCL calls clz out of line. */
inline int lowest_lane(uint mask) { return (as_int((float)(mask & -mask)) >> 23) - 127; }

/* Lanes of a vector by index, without vstore8 (PoCL calls it out of line). */
typedef union {
    float8 v;
    float s[8];
} LanesF;
typedef union {
    int8 v;
    int s[8];
} LanesI;

/* Lane i of a vector (lights.h's all-hits traversal of the emitter BVH). */
inline float lane(float8 v, int i)
{
    switch (i) {
    case 0: return v.s0; case 1: return v.s1; case 2: return v.s2; case 3: return v.s3;
    case 4: return v.s4; case 5: return v.s5; case 6: return v.s6; default: return v.s7;
    }
}

inline int lane_int(int8 v, int i)
{
    switch (i) {
    case 0: return v.s0; case 1: return v.s1; case 2: return v.s2; case 3: return v.s3;
    case 4: return v.s4; case 5: return v.s5; case 6: return v.s6; default: return v.s7;
    }
}

inline float3 tri_vertex(global const float4* v, int slot, int k) { return v[3 * slot + k].xyz; }

/* |v| by masking the sign bits: fabs's bits, without PoCL's out-of-line call. */
inline float8 abs8(float8 v) { return as_float8(as_int8(v) & (int8)(0x7fffffff)); }

/* The up to 8 triangles of leaf block L (rows v0 xyz, v1 xyz, v2 xyz, slot) against r at once:
 * intersect_triangle's arithmetic lane by lane, in the same order and without contraction, so
 * every value is the one it computes. What depends on the closest hit so far (the comparison
 * with hit->t) runs per candidate lane in slot order, as the one-at-a-time loop did, and lanes
 * with an edge function exactly 0 go through intersect_triangle itself (its fp64 fallback).
 * Hence the same hit, to the bit, as testing the triangles one by one. */
inline void intersect_leaf(global const float8* L, int n, const Ray* r, int skip, Hit* hit)
{
#pragma OPENCL FP_CONTRACT OFF
    int kz = r->kz, kx = kz == 2 ? 0 : kz + 1, ky = kz == 0 ? 2 : (kz == 1 ? 0 : 1);
    float3 o = rotate_to_z(r->o, kz);
    const float3 S = r->shear;
    float8 az = L[kz] - o.z, bz = L[3 + kz] - o.z, cz = L[6 + kz] - o.z;
    float8 asx = (L[kx] - o.x) - S.x * az, asy = (L[ky] - o.y) - S.y * az;
    float8 bsx = (L[3 + kx] - o.x) - S.x * bz, bsy = (L[3 + ky] - o.y) - S.y * bz;
    float8 csx = (L[6 + kx] - o.x) - S.x * cz, csy = (L[6 + ky] - o.y) - S.y * cz;
    float8 asz = S.z * az, bsz = S.z * bz, csz = S.z * cz;
    LanesF U = {csx * bsy - csy * bsx}, V = {asx * csy - asy * csx}, W = {bsx * asy - bsy * asx};
    LanesF det = {U.v + V.v + W.v}, T = {U.v * asz + V.v * bsz + W.v * csz};
    LanesF sdet = {abs8(det.v)}, sT = {det.v < 0.0f ? -T.v : T.v};
    int8 zero = (U.v == 0.0f) | (V.v == 0.0f) | (W.v == 0.0f);
    int8 outside = ((U.v < 0.0f) | (V.v < 0.0f) | (W.v < 0.0f)) & ((U.v > 0.0f) | (V.v > 0.0f) | (W.v > 0.0f));
    int8 live = (int8)(0, 1, 2, 3, 4, 5, 6, 7) < n;
    /* candidates in bits 0-7, which of them have an edge function 0 in bits 8-15: one reduction */
    int8 bit = (int8)(1, 2, 4, 8, 16, 32, 64, 128);
    int8 candidate = live & (zero | (~outside & (det.v != 0.0f) & (sT.v > 0.0f)));
    uint lanes = lane_mask_bits(candidate, bit | bit << 8 & zero), candidates = lanes & 255u, edge = lanes >> 8;
    LanesI slots = {as_int8(L[9])};
    for (; candidates; candidates &= candidates - 1) {
        int i = lowest_lane(candidates);
        if (slots.s[i] == skip)
            continue;
        float t, b1, b2;
        if ((edge >> i) & 1) {
            LanesF x0 = {L[0]}, y0 = {L[1]}, z0 = {L[2]}, x1 = {L[3]}, y1 = {L[4]}, z1 = {L[5]};
            LanesF x2 = {L[6]}, y2 = {L[7]}, z2 = {L[8]};
            if (!intersect_triangle(r, (float3)(x0.s[i], y0.s[i], z0.s[i]), (float3)(x1.s[i], y1.s[i], z1.s[i]),
                                    (float3)(x2.s[i], y2.s[i], z2.s[i]), hit->t, &t, &b1, &b2))
                continue;
        } else {
            if (!(sT.s[i] < hit->t * sdet.s[i]))
                continue;
            float inv = 1.0f / det.s[i];
            t = T.s[i] * inv;
            b1 = V.s[i] * inv;
            b2 = W.s[i] * inv;
        }
        hit->t = t;
        hit->slot = slots.s[i];
        hit->b1 = b1;
        hit->b2 = b2;
    }
}

/* Closest hit along r in (0, tmax), ignoring triangle slot `skip` (the one the ray leaves).
 * Per node: the lanes hit, as a bit mask; their leaves' triangles first (in lane order), then
 * the inner lanes pushed far to near, so the nearest is popped first, and popped entries
 * farther than the hit so far are dropped. */
inline Hit bvh_closest_hit(const SceneData* s, const Ray* r, float tmax, int skip)
{
    Hit hit = {tmax, -1, 0.0f, 0.0f};
#ifdef BVH_STATS
    hit.nodes = hit.tris = 0;
#endif
    int stack[BVH_STACK_SIZE];
    float stack_t[BVH_STACK_SIZE];
    int top = 0, node = 0;
    int3 near = near_rows(r);
    for (;;) {
#ifdef BVH_STATS
        ++hit.nodes;
#endif
        float8 entry = lane_entry(s->bvh_bounds + 6 * node, r, near, hit.t);
        int8 child = s->bvh_children[2 * node], count = s->bvh_children[2 * node + 1];
        /* one reduction for both masks: leaves hit in bits 0-7, inner lanes hit in bits 8-15 */
        int8 bit = (int8)(1, 2, 4, 8, 16, 32, 64, 128);
        bit = count > 0 ? bit : bit << 8;
        uint lanes = lane_mask_bits(entry <= hit.t & count >= 0, bit);
        LanesF e = {entry};
        LanesI c = {child}, n = {count};
        for (uint leaves = lanes & 255u; leaves; leaves &= leaves - 1) {
            int i = lowest_lane(leaves);
#ifdef BVH_STATS
            hit.tris += n.s[i];
#endif
            intersect_leaf(s->bvh_leaves + 10 * c.s[i], n.s[i], r, skip, &hit);
        }
        uint inner = lanes >> 8;
        if (inner && !(inner & (inner - 1))) { /* one child: no push and pop */
            int i = lowest_lane(inner);
            if (e.s[i] <= hit.t) {
                node = c.s[i];
                continue;
            }
            inner = 0;
        }
        int first = top;
        for (; inner; inner &= inner - 1) {
            int i = lowest_lane(inner);
            float ti = e.s[i];
            if (top >= BVH_STACK_SIZE)
                break;
            /* insertion into the sorted tail of the stack: descending entry distance */
            int j = top++;
            while (j > first && stack_t[j - 1] < ti) {
                stack[j] = stack[j - 1];
                stack_t[j] = stack_t[j - 1];
                --j;
            }
            stack[j] = c.s[i];
            stack_t[j] = ti;
        }
        do {
            if (top == 0)
                return hit;
            --top;
        } while (stack_t[top] > hit.t);
        node = stack[top];
    }
}

#endif
