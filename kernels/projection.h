#line 2 "projection.h"
/* Pinhole projection of world points to pixels and its derivative, for the boundary term of
 * the geometric gradients (edges.h): the screen velocity of a moving point. Undistorted
 * cameras only (the host refuses others): the projection of a straight edge is then straight. */
#ifndef INVRENDER_PROJECTION_H
#define INVRENDER_PROJECTION_H

#include "camera.h"

inline float3 camera_rotate(global const CameraData* c, float3 v)
{
    return (float3)(c->R[0] * v.x + c->R[1] * v.y + c->R[2] * v.z,
                    c->R[3] * v.x + c->R[4] * v.y + c->R[5] * v.z,
                    c->R[6] * v.x + c->R[7] * v.y + c->R[8] * v.z);
}

/* d/dtheta of the pixel of x when x moves with velocity v: d(f X/Z)/dtheta = f (X' Z - X Z') / Z^2. */
inline float2 project_velocity(global const CameraData* c, float3 x, float3 v)
{
    float3 xc = camera_rotate(c, x - camera_center(c)), vc = camera_rotate(c, v);
    float inv_z2 = 1.0f / (xc.z * xc.z);
    return (float2)(c->fx * (vc.x * xc.z - xc.x * vc.z) * inv_z2, c->fy * (vc.y * xc.z - xc.y * vc.z) * inv_z2);
}

#endif
