#line 2 "textures.h"
/* Parameter-map lookups: nearest texel of the atlas maps (column floor(u W), row
 * floor((1 - v) H), v up) and of the kg cube map (OpenGL face orientation, faces +X -X +Y -Y
 * +Z -Z). Reference: workflow/invrender/scene/cubemap.py (direction_to_cube). Nearest texels
 * make every map value a plain parameter, so the gradient of a pixel lands on whole texels. */
#ifndef INVRENDER_TEXTURES_H
#define INVRENDER_TEXTURES_H

#include "common.h"
#include "scene_data.h"

inline int atlas_texel(const SceneData* s, float2 uv)
{
    int col = clamp((int)floor(uv.x * (float)s->atlas_w), 0, s->atlas_w - 1);
    int row = clamp((int)floor((1.0f - uv.y) * (float)s->atlas_h), 0, s->atlas_h - 1);
    return row * s->atlas_w + col;
}

inline Material material_from(global const float4* buffer, int texel)
{
    float4 a = buffer[3 * texel], b = buffer[3 * texel + 1], c = buffer[3 * texel + 2];
    /* ka = 0 would make D a delta (0/0 at h = n): the model's range starts at KA_MIN, as in the
     * reference (render/bsdf.py) */
    Material m = {a.xyz, b.xyz, c.xyz, fmax(a.w, 1e-6f), b.w};
    return m;
}

inline Material material_at(const SceneData* s, int texel)
{
    return material_from(s->material, texel);
}

/* The material a path samples its next direction from: the same one, except under the
 * FIXED_PROPOSAL test hook (scene_data.h). */
inline Material proposal_at(const SceneData* s, int texel, const Material* m)
{
#ifdef FIXED_PROPOSAL
    return material_from(s->proposal, texel);
#else
    return *m;
#endif
}

/* Face and its coordinates (sc, tc) in [-1, 1] for a direction (OpenGL spec, table 3.21). */
inline int cube_face(float3 d, float* sc, float* tc)
{
    float3 a = fabs(d);
    if (a.x >= a.y && a.x >= a.z) {
        *sc = (d.x > 0.0f ? -d.z : d.z) / a.x;
        *tc = -d.y / a.x;
        return d.x > 0.0f ? 0 : 1;
    }
    if (a.y >= a.z) {
        *sc = d.x / a.y;
        *tc = (d.y > 0.0f ? d.z : -d.z) / a.y;
        return d.y > 0.0f ? 2 : 3;
    }
    *sc = (d.z > 0.0f ? d.x : -d.x) / a.z;
    *tc = -d.y / a.z;
    return d.z > 0.0f ? 4 : 5;
}

/* The direction through face coordinates (sc, tc): the inverse of cube_face. */
inline float3 cube_direction(int face, float sc, float tc)
{
    switch (face) {
    case 0: return normalize((float3)(1.0f, -tc, -sc));
    case 1: return normalize((float3)(-1.0f, -tc, sc));
    case 2: return normalize((float3)(sc, 1.0f, tc));
    case 3: return normalize((float3)(sc, -1.0f, -tc));
    case 4: return normalize((float3)(sc, -tc, 1.0f));
    default: return normalize((float3)(-sc, -tc, -1.0f));
    }
}

inline int cube_texel(int n, int face, float sc, float tc)
{
    int col = clamp((int)floor((sc + 1.0f) * 0.5f * (float)n), 0, n - 1);
    int row = clamp((int)floor((tc + 1.0f) * 0.5f * (float)n), 0, n - 1);
    return (face * n + row) * n + col;
}

inline int cube_texel_of(const SceneData* s, float3 d)
{
    float sc, tc;
    int face = cube_face(d, &sc, &tc);
    return cube_texel(s->cube_n, face, sc, tc);
}

#endif
