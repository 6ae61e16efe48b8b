#line 2 "surface.h"
/* The point a ray hit: position, facing normal, UV, texel, and whether it emits towards the ray.
 * Shared by the path (integrator.h) and the light samples of next-event estimation (nee.h). */
#ifndef INVRENDER_SURFACE_H
#define INVRENDER_SURFACE_H

#include "common.h"
#include "scene_data.h"
#include "bvh.h"
#include "textures.h"
#include "lights.h"

typedef struct {
    float3 p;   /* on the triangle, from barycentrics (more precise than o + t d) */
    float3 n;   /* unit geometric normal, turned to face the incoming ray: two-sided surfaces */
    float2 uv;
    int texel;
    int emits;  /* 0 on the back of a one-sided face, which emits nothing (lights.h) */
} SurfacePoint;

inline SurfacePoint surface_point(const SceneData* s, const Hit* h, float3 d)
{
    float3 v0 = tri_vertex(s->tri_v, h->slot, 0), v1 = tri_vertex(s->tri_v, h->slot, 1),
           v2 = tri_vertex(s->tri_v, h->slot, 2);
    float b0 = 1.0f - h->b1 - h->b2;
    SurfacePoint sp;
    sp.p = b0 * v0 + h->b1 * v1 + h->b2 * v2;
    float3 n = normalize(cross(v1 - v0, v2 - v0));
    sp.n = dot(n, d) > 0.0f ? -n : n;
    sp.emits = emits_towards(s->tri_one_sided, h->slot, n, d);
    global const float2* uv = s->tri_uv + 3 * h->slot;
    sp.uv = b0 * uv[0] + h->b1 * uv[1] + h->b2 * uv[2];
    sp.texel = atlas_texel(s, sp.uv);
    return sp;
}

#endif
