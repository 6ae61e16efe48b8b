#line 2 "common.h"
/* Constants, small vector helpers and the material record, used by most headers (the scene
 * data is scene_data.h's).
 *
 * Feature flags (set by the host from features.json, see workflow/invrender/render/features.py):
 *   FEATURE_SPECULAR          Cook-Torrance lobe (else the material is Lambertian)
 *   FEATURE_EMISSION          ke term of E = ke + kw kg
 *   FEATURE_EMITTER_SAMPLING  strategy 4: emitting triangles by area x radiance
 *   FEATURE_ENVIRONMENT       kg seen by rays that leave the scene
 *   FEATURE_WINDOW            kw kg term on surfaces (needs FEATURE_ENVIRONMENT)
 *   FEATURE_ENV_SAMPLING      strategy 3: kg cube map by luminance (needs FEATURE_ENVIRONMENT)
 *   FEATURE_ONE_SIDED         some faces emit (ke + kw kg) on their front side only
 *   MAX_BOUNCES               scattering events per path (Mitsuba's max_depth - 1)
 */
#ifndef INVRENDER_COMMON_H
#define INVRENDER_COMMON_H

#ifndef MAX_BOUNCES
#define MAX_BOUNCES 10
#endif
#if defined(FEATURE_WINDOW) && !defined(FEATURE_ENVIRONMENT)
#error "FEATURE_WINDOW needs FEATURE_ENVIRONMENT"
#endif
#if defined(FEATURE_ENV_SAMPLING) && !defined(FEATURE_ENVIRONMENT)
#error "FEATURE_ENV_SAMPLING needs FEATURE_ENVIRONMENT"
#endif

#define INV_PI 0.31830988618379067f
#define PI_F 3.14159265358979323f
#define RAY_TMAX 3.0e38f

inline float luminance(float3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }
inline float max3(float3 c) { return fmax(c.x, fmax(c.y, c.z)); }
inline float safe_sqrt(float x) { return sqrt(fmax(x, 0.0f)); }
inline int all_finite3(float3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }

/* Orthonormal basis around n (Duff et al. 2017, "Building an Orthonormal Basis, Revisited"):
 * continuous everywhere but the sign flip, no division by a small number. */
inline void make_frame(float3 n, float3* s, float3* t)
{
    float sign = copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float b = n.x * n.y * a;
    *s = (float3)(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    *t = (float3)(b, sign + n.y * n.y * a, -n.y);
}

inline float3 to_world(float3 v, float3 n)
{
    float3 s, t;
    make_frame(n, &s, &t);
    return v.x * s + v.y * t + v.z * n;
}

/* Material at one texel, unpacked from the three float4 the host stores per texel:
 * [kd.rgb, ka], [ks.rgb, kw], [ke.rgb, -]. */
typedef struct {
    float3 kd, ks, ke;
    float ka, kw;
} Material;

#endif
