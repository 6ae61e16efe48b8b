#line 2 "pose.h"
/* Velocity fields of posed parts (render/silhouette.py): a part's world points are
 * x = R(r) diag(exp(log s)) u + t, an affine map of its own points u, so the velocity of the
 * material point at world x w.r.t. each of the 9 pose parameters (t, axis-angle r, log s) is
 * affine in x: V_j(x) = A_j x + b_j. The host writes them as 3 rows (A_j row k | b_j k) per
 * parameter, 9 parameters per part, in float4. */
#ifndef INVRENDER_POSE_H
#define INVRENDER_POSE_H

#define POSE_PARAMS 9

inline float3 pose_velocity(global const float4* velocity, int part, int j, float3 x)
{
    global const float4* rows = velocity + 3 * (POSE_PARAMS * part + j);
    float4 xh = (float4)(x, 1.0f);
    return (float3)(dot(rows[0], xh), dot(rows[1], xh), dot(rows[2], xh));
}

#endif
