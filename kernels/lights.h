#line 2 "lights.h"
/* MILO's light model, E(x, -d) = ke(x) + kw(x) kg(d) (Eq. 2), and the two light-driven sampling
 * strategies of the mixture: the kg cube map by luminance (3) and the emitting triangles by
 * area x radiance (4). Reference: workflow/invrender/render/sampling.py. */
#ifndef INVRENDER_LIGHTS_H
#define INVRENDER_LIGHTS_H

#include "common.h"
#include "scene_data.h"
#include "intersect.h"
#include "bvh.h"
#include "textures.h"

#ifdef FEATURE_ENVIRONMENT
inline float3 environment(const SceneData* s, float3 d) { return s->kg[cube_texel_of(s, d)].xyz; }
#endif

/* Whether triangle `slot` of a list with flags `one_sided`, with unnormalised counter-clockwise
 * normal n, emits towards a ray travelling in direction d: always, unless it is one-sided and d
 * meets its back (Mitsuba's `area` emitter is one-sided so; a panel just below a ceiling must
 * not light the ceiling behind it). Compiled to 1 without FEATURE_ONE_SIDED. */
inline int emits_towards(global const uchar* one_sided, int slot, float3 n, float3 d)
{
#ifdef FEATURE_ONE_SIDED
    return !one_sided[slot] || dot(n, d) < 0.0f;
#else
    return 1;
#endif
}

/* Radiance a surface with material m sends back along a ray travelling in direction d (on a
 * side of it that emits, see emits_towards). */
inline float3 emitted(const SceneData* s, const Material* m, float3 d)
{
    float3 e = (float3)(0.0f);
#ifdef FEATURE_EMISSION
    e += m->ke;
#endif
#ifdef FEATURE_WINDOW
    if (m->kw > 0.0f)
        e += m->kw * environment(s, d);
#endif
    return e;
}

/* Smallest i with cdf[i] > u (cdf inclusive, last entry 1). */
inline int sample_cdf(global const float* cdf, int n, float u)
{
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (cdf[mid] > u)
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

#ifdef FEATURE_ENV_SAMPLING
/* Strategy 3: a texel by P(texel) ~ luminance x solid angle, then a point uniform in its face
 * coordinates. The solid-angle density is P / (2/N)^2 x (1 + sc^2 + tc^2)^(3/2), the Jacobian
 * of the gnomonic projection of a cube face. */
inline float3 sample_environment(const SceneData* s, float u1, float u2, float u3)
{
    int n = s->cube_n;
    int texel = sample_cdf(s->env_cdf, 6 * n * n, u1);
    int face = texel / (n * n), rc = texel % (n * n);
    float sc = 2.0f * ((float)(rc % n) + u2) / (float)n - 1.0f;
    float tc = 2.0f * ((float)(rc / n) + u3) / (float)n - 1.0f;
    return cube_direction(face, sc, tc);
}

inline float pdf_environment(const SceneData* s, float3 d)
{
    float sc, tc;
    int face = cube_face(d, &sc, &tc);
    int n = s->cube_n;
    float texel_area = 4.0f / (float)(n * n);
    float r2 = 1.0f + sc * sc + tc * tc;
    return s->env_pmf[cube_texel(n, face, sc, tc)] / texel_area * r2 * sqrt(r2);
}
#endif

#ifdef FEATURE_EMITTER_SAMPLING
/* Strategy 4: an emitting triangle by P(t) ~ area x mean luminance of ke, then a point uniform on
 * it (b0 = 1 - sqrt(u2), b1 = u3 sqrt(u2)). Returns the point and sets *t to the triangle (its
 * emitter-BVH slot). */
inline float3 sample_emitter_point(const SceneData* s, float u1, float u2, float u3, int* t)
{
    *t = sample_cdf(s->em_cdf, s->num_emitters, u1);
    float su = sqrt(u2);
    float b0 = 1.0f - su, b1 = u3 * su;
    float3 v0 = tri_vertex(s->em_v, *t, 0), v1 = tri_vertex(s->em_v, *t, 1), v2 = tri_vertex(s->em_v, *t, 2);
    return b0 * v0 + b1 * v1 + (1.0f - b0 - b1) * v2;
}

/* Whether emitting triangle t sends light from its point y towards x (see emits_towards). */
inline int emitter_faces(const SceneData* s, int t, float3 y, float3 x)
{
    float3 v0 = tri_vertex(s->em_v, t, 0), v1 = tri_vertex(s->em_v, t, 1), v2 = tri_vertex(s->em_v, t, 2);
    return emits_towards(s->em_one_sided, t, cross(v1 - v0, v2 - v0), y - x);
}

/* Strategy 4 as a direction from x: the unit direction to the sampled point, or (0, 0, 0), a
 * spent sample, for a point on a one-sided triangle that x sees from behind: it sends nothing
 * towards x, and pdf_emitter leaves such crossings out, so the density stays the sampler's. */
inline float3 sample_emitter(const SceneData* s, float3 x, float u1, float u2, float u3)
{
    int t;
    float3 y = sample_emitter_point(s, u1, u2, u3, &t);
    return emitter_faces(s, t, y, x) ? normalize(y - x) : (float3)(0.0f);
}

/* Solid-angle density of strategy 4 at direction d from x: every emitting triangle the ray
 * crosses could have produced d, not only the first one hit ("all hits", MILO sec. 3.5), so the
 * emitter BVH is traversed to the end and each crossing adds P(t)/area(t) dist^2 / |cos|. */
inline float pdf_emitter(const SceneData* s, float3 x, float3 d)
{
    Ray r = make_ray(x, d);
    float pdf = 0.0f;
    int stack[BVH_STACK_SIZE];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
        int node = stack[--top];
        float8 entry = bvh_lane_entry(s->em_bounds, node, &r, RAY_TMAX);
        int8 child = s->em_children[2 * node], count = s->em_children[2 * node + 1];
        for (int i = 0; i < 8; ++i) {
            if (!(lane(entry, i) < INFINITY))
                continue;
            int n = lane_int(count, i), c = lane_int(child, i);
            if (n == 0 && top < BVH_STACK_SIZE)
                stack[top++] = c;
            for (int slot = c; n > 0 && slot < c + n; ++slot) {
                float3 v0 = tri_vertex(s->em_v, slot, 0), v1 = tri_vertex(s->em_v, slot, 1),
                       v2 = tri_vertex(s->em_v, slot, 2);
                float t, b1, b2;
                if (intersect_triangle(&r, v0, v1, v2, RAY_TMAX, &t, &b1, &b2)) {
                    float3 ng = normalize(cross(v1 - v0, v2 - v0));
                    if (emits_towards(s->em_one_sided, slot, ng, d))
                        pdf += s->em_pdf_area[slot] * t * t / fabs(dot(ng, d));
                }
            }
        }
    }
    return pdf;
}
#endif

#endif
