#line 2 "sampling.h"
/* MILO's mixture of four sampling strategies with the mixture's density (one-sample MIS):
 * whichever strategy drew wi, the path weight is f cos / sum_k w_k p_k(wi). Strategies the scene
 * does not call for are compiled out and get weight 0. docs/renderer.md gives the weights. */
#ifndef INVRENDER_SAMPLING_H
#define INVRENDER_SAMPLING_H

#include "common.h"
#include "scene_data.h"
#include "bsdf.h"
#include "lights.h"

typedef struct {
    float diffuse, specular, env, emit;
} MixtureWeights;

/* w_env, w_emit: the light strategies' weights (s->w_env, s->w_emit in MILO's mixture; 0 and 0
 * for the BSDF sampling of next-event estimation, nee.h, which samples the lights on its own).
 * The BSDF share (1 - w_env - w_emit) is split by the lobes' luminance (F at normal incidence is
 * ks): all three Rec. 709 weights are positive, so a lobe with any reflectance is sampled with
 * some probability and no unbiasedness is lost. */
inline MixtureWeights mixture_weights(float w_env, float w_emit, const Material* m)
{
    MixtureWeights w = {0.0f, 0.0f, 0.0f, 0.0f};
#ifdef FEATURE_ENV_SAMPLING
    w.env = w_env;
#endif
#ifdef FEATURE_EMITTER_SAMPLING
    w.emit = w_emit;
#endif
    float d = luminance(m->kd), sp = 0.0f;
#ifdef FEATURE_SPECULAR
    sp = luminance(m->ks);
#endif
    float share = 1.0f - w.env - w.emit;
    if (d + sp > 0.0f) {
        w.diffuse = share * d / (d + sp);
        w.specular = share * sp / (d + sp);
    }
    return w;
}

inline int reflects(const MixtureWeights* w) { return w->diffuse + w->specular > 0.0f; }

/* x: the point the direction leaves from (for strategy 4); u.x picks the strategy. Returns
 * (0, 0, 0) for a spent sample. */
inline float3 sample_mixture(const SceneData* s, const MixtureWeights* w, const Material* m,
                             float3 x, float3 n, float3 wo, float4 u)
{
    float pick = u.x;
    if (pick < w->diffuse)
        return sample_cosine(n, u.y, u.z);
    pick -= w->diffuse;
#ifdef FEATURE_SPECULAR
    if (pick < w->specular)
        return sample_specular(n, wo, m->ka, u.y, u.z);
    pick -= w->specular;
#endif
#ifdef FEATURE_ENV_SAMPLING
    if (pick < w->env)
        return sample_environment(s, u.y, u.z, u.w);
    pick -= w->env;
#endif
#ifdef FEATURE_EMITTER_SAMPLING
    if (w->emit > 0.0f)
        return sample_emitter(s, x, u.y, u.z, u.w);
#endif
    return sample_cosine(n, u.y, u.z); /* rounding at pick ~ 1 */
}

inline float pdf_mixture(const SceneData* s, const MixtureWeights* w, const Material* m, float3 x,
                         float3 n, float3 wo, float3 wi)
{
    float pdf = w->diffuse * pdf_cosine(n, wi);
#ifdef FEATURE_SPECULAR
    if (w->specular > 0.0f)
        pdf += w->specular * pdf_specular(n, wo, wi, m->ka);
#endif
    /* A strategy with weight 0 has nothing to sample (a black sky, no emitters): its density is
     * not even evaluated, so no 0 x garbage can reach the sum. */
#ifdef FEATURE_ENV_SAMPLING
    if (w->env > 0.0f)
        pdf += w->env * pdf_environment(s, wi);
#endif
#ifdef FEATURE_EMITTER_SAMPLING
    if (w->emit > 0.0f)
        pdf += w->emit * pdf_emitter(s, x, wi);
#endif
    return pdf;
}

#endif
