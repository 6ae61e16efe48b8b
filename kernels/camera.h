#line 2 "camera.h"
/* Camera rays for COLMAP cameras: world-to-camera x_cam = R x_world + t, OpenCV axes (x right,
 * y down, z forward), pixel (0, 0)'s centre at (0.5, 0.5). PINHOLE, SIMPLE_PINHOLE (fx = fy) and
 * OPENCV (radial k1 k2, tangential p1 p2, undistorted by fixed-point iteration). A panorama is
 * six 90-degree pinhole cameras, one per cube face, so it needs nothing more here. */
#ifndef INVRENDER_CAMERA_H
#define INVRENDER_CAMERA_H

/* The host packs one of these per camera (CAMERA_DTYPE in render/scene_buffers.py). */
typedef struct {
    float R[9];   /* world-to-camera rotation, row major */
    float C[3];   /* camera centre in world coordinates (-R^T t, computed in float64) */
    float fx, fy, cx, cy;
    float k1, k2, p1, p2;
    int width, height, distorted, pad;
} CameraData;

/* Invert the OpenCV distortion (x_d = x (1 + k1 r^2 + k2 r^4) + tangential) by the fixed-point
 * iteration OpenCV's undistortPoints uses; converges for the mild distortion of real lenses. */
inline float2 undistort(global const CameraData* c, float2 xd)
{
    float2 x = xd;
    for (int it = 0; it < 8; ++it) {
        float r2 = dot(x, x);
        float radial = 1.0f + r2 * (c->k1 + r2 * c->k2);
        float2 tangential = (float2)(2.0f * c->p1 * x.x * x.y + c->p2 * (r2 + 2.0f * x.x * x.x),
                                     c->p1 * (r2 + 2.0f * x.y * x.y) + 2.0f * c->p2 * x.x * x.y);
        x = (xd - tangential) / radial;
    }
    return x;
}

/* World-space unit direction through image point (px, py) in pixels. */
inline float3 camera_direction(global const CameraData* c, float px, float py)
{
    float2 x = (float2)((px - c->cx) / c->fx, (py - c->cy) / c->fy);
    if (c->distorted)
        x = undistort(c, x);
    /* d_world = R^T d_cam */
    float3 dc = (float3)(x.x, x.y, 1.0f);
    float3 d = (float3)(c->R[0] * dc.x + c->R[3] * dc.y + c->R[6] * dc.z,
                        c->R[1] * dc.x + c->R[4] * dc.y + c->R[7] * dc.z,
                        c->R[2] * dc.x + c->R[5] * dc.y + c->R[8] * dc.z);
    return normalize(d);
}

inline float3 camera_center(global const CameraData* c) { return (float3)(c->C[0], c->C[1], c->C[2]); }

/* Depth along the optical axis (COLMAP depth maps), for a hit at distance t along unit d. */
inline float camera_depth(global const CameraData* c, float3 d, float t)
{
    return t * (c->R[6] * d.x + c->R[7] * d.y + c->R[8] * d.z);
}

#endif
