#line 2 "adjoint.cl"
/* The adjoint of render.cl: for each ray request and its adjoint radiance dLoss/dL (already
 * divided by the sample count), d Loss / d(texel) of every parameter map, accumulated over all
 * samples. Each sample's path is traced exactly as the forward kernel traces it (same random
 * numbers) and recorded whole (at most MAX_BOUNCES + 2 vertices), then walked backwards:
 * R, the radiance leaving the vertex after the current one, gives the derivative through the
 * current vertex's BSDF, dL/dtheta = beta * (d f cos / d theta) / p * R, and with next-event
 * estimation the light sample's f E w / p_l likewise. Sampling is detached (MILO sec. 3.2): p,
 * and the MIS weights w (as Mitsuba's prb holds them), are constants; the weights of the two
 * samples that can find the same light still sum to 1, so the gradient stays unbiased for the
 * expected image.
 *
 * Two accumulation modes, chosen at compile time:
 * - default, deterministic: 64-bit fixed-point integers (value x scale, rounded) added with
 *   atom_add, which is order independent, so the same seed gives the same bytes on one device.
 *   Each map has its own scale. Each work-item keeps the largest |value| it added per map and
 *   the launch keeps the largest of those (`peaks`), so the host can tell when a scale left too
 *   little headroom or too little resolution and run the pass again with better ones
 *   (render/adjoint.py).
 * - ACCUMULATE_BUCKETS: MILO's scheme. NUM_BUCKETS float copies of the gradient maps; a ray adds
 *   into copy (ray id mod NUM_BUCKETS) with a compare-and-swap float add (OpenCL 1.2 has no float
 *   atomics), so rays that hit the same texel at once rarely touch the same word; reduce_buckets
 *   sums the copies. The order of float additions varies from run to run. */
#include "common.h"
#include "scene_data.h"
#include "camera.h"
#include "textures.h"
#include "bsdf.h"
#include "lights.h"
#include "integrator.h"

/* The layouts come from the host (LAYOUT_DEFINES in workflow/invrender/render/adjoint.py, made
 * from the map list of workflow/invrender/scene/types.py): GRAD_KD, GRAD_KS, GRAD_KA, GRAD_KE,
 * GRAD_KW, the first channel of each atlas map in a texel's GRAD_CHANNELS gradient channels, and
 * MAP_KD ... MAP_KG < GRAD_MAPS, the maps' indices. Each map has its own fixed-point scale: their
 * derivatives can lie ten orders of magnitude apart (d/dka of a mirror against d/dke), and one
 * scale cannot resolve both. */
#if !defined(GRAD_CHANNELS) || !defined(GRAD_MAPS)
#error "adjoint.cl: build it with render/adjoint.py's LAYOUT_DEFINES (the gradient layout)"
#endif

/* The maps whose gradient is wanted, a bit per MAP_* index (render/adjoint.py's wanted_defines):
 * the others' additions are compiled out (`map` is a constant at every call). */
#ifndef GRAD_WANTED
#define GRAD_WANTED ((1 << GRAD_MAPS) - 1)
#endif
#define WANTED(map) (((GRAD_WANTED) >> (map)) & 1)

typedef struct {
    float scale[GRAD_MAPS]; /* fixed point: units per 1.0, a power of two */
    float peak[GRAD_MAPS];  /* largest |value| this work-item added */
} Accumulator;

#ifdef ACCUMULATE_BUCKETS
typedef float grad_t;

/* A float atomic add by compare-and-swap on the word's bits. */
inline void add_grad(global grad_t* target, float value, Accumulator* acc, int map)
{
    if (!WANTED(map) || value == 0.0f || !isfinite(value))
        return;
    volatile global uint* word = (volatile global uint*)target;
    uint expected = *word, seen;
    while ((seen = atomic_cmpxchg(word, expected, as_uint(as_float(expected) + value))) != expected)
        expected = seen;
}
#else
/* 64-bit atom_add is an extension (NVIDIA's and AMD's drivers and PoCL report it); the buckets
 * build above never needs it. The host picks buckets where a device lacks it (render/adjoint.py),
 * so this only fires on a hand-made build. */
#ifndef cl_khr_int64_base_atomics
#error "adjoint.cl: fixed-point accumulation needs cl_khr_int64_base_atomics; build with -D ACCUMULATE_BUCKETS"
#endif
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
typedef long grad_t;

inline void add_grad(global grad_t* target, float value, Accumulator* acc, int map)
{
    if (WANTED(map) && value != 0.0f && isfinite(value)) {
        atom_add(target, (long)rint(value * acc->scale[map])); /* a power of two: exact */
        acc->peak[map] = fmax(acc->peak[map], fabs(value));
    }
}
#endif

inline void add_grad3(global grad_t* target, float3 value, Accumulator* acc, int map)
{
    add_grad(target, value.x, acc, map);
    add_grad(target + 1, value.y, acc, map);
    add_grad(target + 2, value.z, acc, map);
}

/* Adds the derivatives of weight x E, the radiance that texel `texel` (-1: the sky) sends along
 * d, to its ke, kw and kg, and returns E. */
inline float3 backpropagate_emission(const SceneData* s, int texel, float3 d, float3 weight, global grad_t* grad_atlas,
                                     global grad_t* grad_kg, Accumulator* acc)
{
    if (texel < 0) {
#ifdef FEATURE_ENVIRONMENT
        add_grad3(grad_kg + 3 * cube_texel_of(s, d), weight, acc, MAP_KG);
        return environment(s, d);
#else
        return (float3)(0.0f);
#endif
    }
    Material m = material_at(s, texel);
#ifdef FEATURE_EMISSION
    add_grad3(grad_atlas + GRAD_CHANNELS * texel + GRAD_KE, weight, acc, MAP_KE);
#endif
#ifdef FEATURE_WINDOW
    add_grad(grad_atlas + GRAD_CHANNELS * texel + GRAD_KW, dot(weight, environment(s, d)), acc, MAP_KW);
    add_grad3(grad_kg + 3 * cube_texel_of(s, d), weight * m.kw, acc, MAP_KG);
#endif
    return emitted(s, &m, d);
}

/* Adds through x d(f cos)/d(kd, ks, ka) for the direction wi to the texel's gradients g. */
inline void backpropagate_bsdf(const Material* m, float3 n, float3 wo, float3 wi, float3 through, global grad_t* g,
                               Accumulator* acc)
{
    float3 d_kd, d_ks, d_ka;
    bsdf_cos_gradients(m, n, wo, wi, &d_kd, &d_ks, &d_ka);
    add_grad3(g + GRAD_KD, through * d_kd, acc, MAP_KD);
#ifdef FEATURE_SPECULAR
    add_grad3(g + GRAD_KS, through * d_ks, acc, MAP_KS);
    add_grad(g + GRAD_KA, dot(through, d_ka), acc, MAP_KA);
#endif
}

/* R is the radiance leaving the vertex after the current one towards it; L, what leaves the
 * current one: its weighted E, its light sample's f E weight, and f R / p through its BSDF sample. */
inline void backpropagate_path(const SceneData* s, const PathVertex* path, int length, float3 adjoint,
                               global grad_t* grad_atlas, global grad_t* grad_kg, Accumulator* acc)
{
    float3 R = (float3)(0.0f);
    for (int b = length - 1; b >= 0; --b) {
        PathVertex v = path[b];
        float3 weight = adjoint * v.beta;
        if (v.texel < 0) {
            R = v.mis * backpropagate_emission(s, -1, v.d, weight * v.mis, grad_atlas, grad_kg, acc);
            continue;
        }
        Material m = material_at(s, v.texel);
        global grad_t* g = grad_atlas + GRAD_CHANNELS * v.texel;
        float3 wo = -v.d, L = (float3)(0.0f); /* nothing, and no derivative, from the back of a one-sided face */
        if (v.emits)
            L = v.mis * backpropagate_emission(s, v.texel, v.d, weight * v.mis, grad_atlas, grad_kg, acc);
#ifdef NEE_ACTIVE
        if (v.light.weight > 0.0f) {
            float3 f = bsdf_cos(&m, v.n, wo, v.light.d);
            backpropagate_bsdf(&m, v.n, wo, v.light.d, weight * v.light.E * v.light.weight, g, acc);
            backpropagate_emission(s, v.light.texel, v.light.d, weight * f * v.light.weight, grad_atlas, grad_kg, acc);
            L += f * v.light.E * v.light.weight;
        }
#endif
        if (v.inv_pdf > 0.0f) {
            backpropagate_bsdf(&m, v.n, wo, v.wi, weight * R * v.inv_pdf, g, acc);
            L += bsdf_cos(&m, v.n, wo, v.wi) * v.inv_pdf * R;
        }
        R = L;
    }
}

kernel void adjoint_rays(SCENE_PARAMS, global const CameraData* cameras, global const int4* requests,
                         int num_requests, ulong seed, uint sample_start, uint sample_count,
                         global const float4* adjoint, global grad_t* grad_atlas, global grad_t* grad_kg,
                         int atlas_stride, int kg_stride, global const float* scales, volatile global int* peaks)
{
    int i = get_global_id(0);
    if (i >= num_requests)
        return;
    SCENE_INIT(s);
    int4 q = requests[i];
#ifdef ACCUMULATE_BUCKETS
    int bucket = (int)((uint)q.w % NUM_BUCKETS);
    grad_atlas += (long)bucket * atlas_stride;
    grad_kg += (long)bucket * kg_stride;
#endif
    Accumulator acc;
    for (int map = 0; map < GRAD_MAPS; ++map) {
        acc.scale[map] = scales[map];
        acc.peak[map] = 0.0f;
    }
    global const CameraData* cam = cameras + q.x;
    float3 delta = adjoint[i].xyz;
    PathVertex path[PATH_CAPACITY];
    for (uint k = sample_start; k < sample_start + sample_count; ++k) {
        float3 d = camera_sample_direction(cam, q, seed, k);
        int suspect = 0, length = 0;
        float3 L = trace_path(&s, camera_center(cam), d, seed, (uint)q.w, k, &suspect, path, &length);
        if (all_finite3(L))
            backpropagate_path(&s, path, length, delta, grad_atlas, grad_kg, &acc);
    }
    for (int map = 0; map < GRAD_MAPS; ++map)
        if (acc.peak[map] > 0.0f)
            atomic_max(peaks + map, as_int(acc.peak[map])); /* non-negative floats order as their bits */
}

/* Sums the NUM_BUCKETS copies (each `stride` floats) into the first, in bucket order. */
kernel void reduce_buckets(global float* buckets, int stride, int num_buckets)
{
    int i = get_global_id(0);
    if (i >= stride)
        return;
    float sum = 0.0f;
    for (int b = 0; b < num_buckets; ++b)
        sum += buckets[(long)b * stride + i];
    buckets[i] = sum;
}
