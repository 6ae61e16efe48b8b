#line 2 "bsdf.h"
/* MILO's material (Eq. 3) in its energy-consistent form: Lambert kd/pi plus a Cook-Torrance lobe
 * with Beckmann D (ka = alpha^2), V-cavity G and Schlick F with the F90 = min(1, 50 ks) clamp,
 * over 4 (n.wi)(n.wo) (Walter et al. 2007). docs/renderer.md states why; the float64 reference is
 * workflow/invrender/render/bsdf.py. All directions point away from the surface, n is on wo's
 * side. Functions return f * cos(theta_i), the weight a path carries. */
#ifndef INVRENDER_BSDF_H
#define INVRENDER_BSDF_H

#include "common.h"

/* Beckmann D from tan^2 of the half-vector angle. tan^2 comes from |n x h|^2, which keeps full
 * precision near the peak; (cos^2 - 1) / cos^2 would cancel to noise when ka is 1e-6. */
inline float beckmann_d(float cos_h, float tan2_h, float ka)
{
    float c2 = cos_h * cos_h;
    return exp(-tan2_h / ka) / (PI_F * ka * c2 * c2);
}

inline float tan2_between(float3 n, float3 h, float cos_h)
{
    float3 c = cross(n, h);
    return dot(c, c) / (cos_h * cos_h);
}

inline float3 schlick_fresnel(float3 ks, float cos_wi_h)
{
    float m = clamp(1.0f - cos_wi_h, 0.0f, 1.0f);
    float m2 = m * m;
    return ks + (fmin(50.0f * ks, (float3)(1.0f)) - ks) * (m2 * m2 * m);
}

/* The specular term f_s * cos_i for wi, wo above the surface (ci, co > 0). */
inline float3 specular_cos(const Material* m, float3 n, float3 wo, float3 wi, float ci, float co)
{
    float3 hsum = wi + wo;
    float len2 = dot(hsum, hsum);
    if (!(len2 > 1e-12f))
        return (float3)(0.0f);
    float3 h = hsum * rsqrt(len2);
    float ch = dot(n, h), hi = dot(wi, h);
    if (!(ch > 0.0f) || !(hi > 0.0f))
        return (float3)(0.0f);
    float D = beckmann_d(ch, tan2_between(n, h, ch), m->ka);
    float G = fmin(1.0f, fmin(2.0f * ch * co / hi, 2.0f * ch * ci / hi));
    return schlick_fresnel(m->ks, hi) * (D * G / (4.0f * co));
}

inline float3 bsdf_cos(const Material* m, float3 n, float3 wo, float3 wi)
{
    float ci = dot(n, wi), co = dot(n, wo);
    if (!(ci > 0.0f) || !(co > 0.0f))
        return (float3)(0.0f);
    float3 f = m->kd * (INV_PI * ci);
#ifdef FEATURE_SPECULAR
    f += specular_cos(m, n, wo, wi, ci, co);
#endif
    return f;
}

/* Partial derivatives of bsdf_cos per channel: d/dkd, d/dks (each channel on its own) and d/dka
 * (one ka for the three channels). Sampling stays detached: the pdf is not differentiated. */
inline void bsdf_cos_gradients(const Material* m, float3 n, float3 wo, float3 wi, float3* d_kd, float3* d_ks,
                               float3* d_ka)
{
    *d_kd = *d_ks = *d_ka = (float3)(0.0f);
    float ci = dot(n, wi), co = dot(n, wo);
    if (!(ci > 0.0f) || !(co > 0.0f))
        return;
    *d_kd = (float3)(INV_PI * ci);
#ifdef FEATURE_SPECULAR
    float3 hsum = wi + wo;
    float len2 = dot(hsum, hsum);
    if (!(len2 > 1e-12f))
        return;
    float3 h = hsum * rsqrt(len2);
    float ch = dot(n, h), hi = dot(wi, h);
    if (!(ch > 0.0f) || !(hi > 0.0f))
        return;
    float tan2 = tan2_between(n, h, ch);
    float D = beckmann_d(ch, tan2, m->ka);
    float G = fmin(1.0f, fmin(2.0f * ch * co / hi, 2.0f * ch * ci / hi));
    float mm = clamp(1.0f - hi, 0.0f, 1.0f), m5 = mm * mm * mm * mm * mm;
    /* F = ks + (min(1, 50 ks) - ks) m5 */
    float3 dF = (float3)(1.0f - m5) + select((float3)(0.0f), (float3)(50.0f * m5), 50.0f * m->ks < (float3)(1.0f));
    float common = G / (4.0f * co);
    *d_ks = dF * (D * common);
    /* D = exp(-t / ka) / (pi ka c^4): dD/dka = D (t - ka) / ka^2 */
    *d_ka = schlick_fresnel(m->ks, hi) * (D * (tan2 - m->ka) / (m->ka * m->ka) * common);
#endif
}

/* Strategy 1: cosine-weighted hemisphere (Malley's method: a uniform disk point, polar mapping,
 * lifted to the hemisphere), the same mapping as the reference so samples compare one to one. */
inline float3 sample_cosine(float3 n, float u1, float u2)
{
    float r = sqrt(u1), phi = 2.0f * PI_F * u2;
    return to_world((float3)(r * cos(phi), r * sin(phi), safe_sqrt(1.0f - u1)), n);
}

inline float pdf_cosine(float3 n, float3 wi) { return fmax(dot(n, wi), 0.0f) * INV_PI; }

/* Strategy 2: Beckmann half vector, wi its mirror of wo. Returns (0, 0, 0) when wi falls below
 * the surface (the sample is spent; pdf_specular integrates to the success probability). */
inline float3 sample_specular(float3 n, float3 wo, float ka, float u1, float u2)
{
    float tan2 = -ka * log1p(-u1);
    float cos_h = rsqrt(1.0f + tan2);
    float sin_h = sqrt(tan2) * cos_h;
    float phi = 2.0f * PI_F * u2;
    float3 h = to_world((float3)(sin_h * cos(phi), sin_h * sin(phi), cos_h), n);
    float3 wi = 2.0f * dot(wo, h) * h - wo;
    return dot(n, wi) > 0.0f ? normalize(wi) : (float3)(0.0f);
}

inline float pdf_specular(float3 n, float3 wo, float3 wi, float ka)
{
    if (!(dot(n, wi) > 0.0f))
        return 0.0f;
    float3 hsum = wi + wo;
    float len2 = dot(hsum, hsum);
    if (!(len2 > 1e-12f))
        return 0.0f;
    float3 h = hsum * rsqrt(len2);
    float ch = dot(n, h), oh = dot(wo, h);
    if (!(ch > 0.0f) || !(oh > 0.0f))
        return 0.0f;
    return beckmann_d(ch, tan2_between(n, h, ch), ka) * ch / (4.0f * oh);
}

#endif
