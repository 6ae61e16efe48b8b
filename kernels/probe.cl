#line 2 "probe.cl"
/* Entry kernels that expose single device functions to the tests (run by tests/render/probe.py
 * for tests/render/test_kernel_*.py): each case gets the kernel's float32 answer, compared there
 * with the float64 reference. */
#include "common.h"
#include "scene_data.h"
#include "rng.h"
#include "intersect.h"
#include "bvh.h"
#include "camera.h"
#include "textures.h"
#include "bsdf.h"
#include "sampling.h"
#include "surface.h"
#include "nee.h"

/* Per case: f cos, and the densities of strategies 1 and 2 (x: diffuse pdf, y: specular pdf). */
kernel void probe_bsdf(global const float4* materials, global const float4* n, global const float4* wo,
                       global const float4* wi, global float4* f_cos, global float2* pdfs)
{
    int i = get_global_id(0);
    Material m = material_from(materials, i);
    float3 nn = n[i].xyz, o = wo[i].xyz, d = wi[i].xyz;
    f_cos[i] = (float4)(bsdf_cos(&m, nn, o, d), 0.0f);
    pdfs[i] = (float2)(pdf_cosine(nn, d), pdf_specular(nn, o, d, m.ka));
}

/* Per case: a cosine sample (u.x, u.y) and a specular sample (u.z, u.w, with ka). */
kernel void probe_lobe_samples(global const float4* n, global const float4* wo, global const float* ka,
                               global const float4* u, global float4* cosine, global float4* specular)
{
    int i = get_global_id(0);
    float4 r = u[i];
    cosine[i] = (float4)(sample_cosine(n[i].xyz, r.x, r.y), 0.0f);
    specular[i] = (float4)(sample_specular(n[i].xyz, wo[i].xyz, ka[i], r.z, r.w), 0.0f);
}

kernel void probe_rng(ulong seed, global const uint4* counters, global float4* out)
{
    int i = get_global_id(0);
    uint4 c = counters[i];
    out[i] = rng_uniform4(seed, c.x, c.y, c.z, c.w);
}

/* The whole mixture at a surface point with material texel `texel`: a sampled direction, and
 * for that direction the mixture density, f cos, and the four strategy densities. */
kernel void probe_mixture(SCENE_PARAMS, global const int* texel, global const float4* x,
                          global const float4* n, global const float4* wo, global const float4* u,
                          global float4* wi_out, global float4* pdf_out, global float4* f_out)
{
    int i = get_global_id(0);
    SCENE_INIT(s);
    Material m = material_at(&s, texel[i]);
    MixtureWeights w = mixture_weights(s.w_env, s.w_emit, &m);
    float3 p = x[i].xyz, nn = n[i].xyz, o = wo[i].xyz;
    float3 wi = sample_mixture(&s, &w, &m, p, nn, o, u[i]);
    wi_out[i] = (float4)(wi, pdf_mixture(&s, &w, &m, p, nn, o, wi));
    f_out[i] = (float4)(bsdf_cos(&m, nn, o, wi), 0.0f);
    float4 parts = (float4)(pdf_cosine(nn, wi), 0.0f, 0.0f, 0.0f);
#ifdef FEATURE_SPECULAR
    parts.y = pdf_specular(nn, o, wi, m.ka);
#endif
#ifdef FEATURE_ENV_SAMPLING
    parts.z = pdf_environment(&s, wi);
#endif
#ifdef FEATURE_EMITTER_SAMPLING
    parts.w = pdf_emitter(&s, p, wi);
#endif
    pdf_out[i] = parts;
}

/* The mixture density of given directions (for chi-square tests of the sampler above). */
kernel void probe_mixture_pdf(SCENE_PARAMS, global const int* texel, global const float4* x,
                              global const float4* n, global const float4* wo, global const float4* wi,
                              global float* pdf_out)
{
    int i = get_global_id(0);
    SCENE_INIT(s);
    Material m = material_at(&s, texel[i]);
    MixtureWeights w = mixture_weights(s.w_env, s.w_emit, &m);
    pdf_out[i] = pdf_mixture(&s, &w, &m, x[i].xyz, n[i].xyz, wo[i].xyz, wi[i].xyz);
}

/* Closest hits of arbitrary rays: (t, b1, b2, original triangle or -1). */
kernel void probe_intersect(SCENE_PARAMS, global const float4* origin, global const float4* direction,
                            global float4* out)
{
    int i = get_global_id(0);
    SCENE_INIT(s);
    Ray r = make_ray(origin[i].xyz, direction[i].xyz);
    Hit h = bvh_closest_hit(&s, &r, RAY_TMAX, -1);
    out[i] = (float4)(h.t, h.b1, h.b2, h.slot < 0 ? -1.0f : (float)s.tri_id[h.slot]);
}

/* Ray origins offset off a surface point, as the integrator does (self-intersection tests). */
kernel void probe_offset(global const float4* p, global const float4* n, global float4* out)
{
    int i = get_global_id(0);
    out[i] = (float4)(offset_ray_origin(p[i].xyz, n[i].xyz), 0.0f);
}

kernel void probe_camera(global const CameraData* cameras, global const float2* pixel, global float4* out)
{
    int i = get_global_id(0);
    out[i] = (float4)(camera_direction(cameras, pixel[i].x, pixel[i].y), 0.0f);
}

#ifdef NEE_ACTIVE
/* Next-event estimation's light sample from x (already off the surface) with material texel
 * `texel`: the direction (w = 1 where the sample found a segment to weigh, 0 where it was spent:
 * occluded, below the surface or the back of a one-sided emitter). */
kernel void probe_light(SCENE_PARAMS, global const int* texel, global const float4* x, global const float4* n,
                        global const float4* wo, global const float4* u, global float4* out)
{
    int i = get_global_id(0);
    SCENE_INIT(s);
    Material m = material_at(&s, texel[i]);
    MixtureWeights w = mixture_weights(0.0f, 0.0f, &m);
    LightChoice c = light_choice(&s);
    int suspect = 0;
    LightSample ls = sample_light(&s, &c, &w, &m, x[i].xyz, n[i].xyz, wo[i].xyz, -1, u[i], &suspect);
    out[i] = (float4)(ls.d, ls.weight > 0.0f && !suspect ? 1.0f : 0.0f);
}

/* The light density of the segment from x along d (to its first hit), 0 for a direction below
 * the surface or onto the back of a one-sided emitter: what probe_light's directions follow. */
kernel void probe_light_pdf(SCENE_PARAMS, global const float4* x, global const float4* n, global const float4* d,
                            global float* pdf_out)
{
    int i = get_global_id(0);
    SCENE_INIT(s);
    LightChoice c = light_choice(&s);
    float3 dir = d[i].xyz;
    Ray ray = make_ray(x[i].xyz, dir);
    Hit hit = bvh_closest_hit(&s, &ray, RAY_TMAX, -1);
    SurfacePoint sp;
    if (hit.slot >= 0)
        sp = surface_point(&s, &hit, dir);
    int seen = dot(dir, n[i].xyz) > 0.0f && (hit.slot < 0 || sp.emits);
    pdf_out[i] = seen ? light_pdf(&s, &c, dir, &hit, &sp) : 0.0f;
}
#endif
