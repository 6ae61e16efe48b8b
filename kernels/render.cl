#line 2 "render.cl"
/* Entry kernels of the forward renderer. They only orchestrate: the path is integrator.h's.
 * A ray request is int4 (camera, pixel x, pixel y, ray id); the ray id keys the random numbers,
 * so a pixel renders the same whether it comes in a full image or in a random batch. */
#include "common.h"
#include "scene_data.h"
#include "intersect.h"
#include "bvh.h"
#include "camera.h"
#include "integrator.h"

/* Adds samples [sample_start, sample_start + sample_count) of each request to accum (sum of
 * L - shift, w = number of non-finite samples dropped) and accum_sq (sum of (L - shift)^2, for
 * error bars; w = number of paths ended on a suspect density or weight). shift is the request's
 * first finite sample, set by the launch that starts at sample 0: sums of squares about a value
 * near the mean keep the variance from cancelling to float noise (L^2 sums lose it when the
 * variance is below ~1e-7 of L^2, as where NEE makes a pixel nearly noiseless). Long renders are
 * split into several launches by the host (progress, GPU watchdogs). */
kernel void render_rays(SCENE_PARAMS, global const CameraData* cameras,
                        global const int4* requests, int num_requests, ulong seed,
                        uint sample_start, uint sample_count, global float4* accum,
                        global float4* accum_sq, global float4* shift)
{
    int i = get_global_id(0);
    if (i >= num_requests)
        return;
    SCENE_INIT(s);
    int4 q = requests[i];
    global const CameraData* cam = cameras + q.x;
    float3 sum = (float3)(0.0f), sum_sq = (float3)(0.0f);
    float dropped = 0.0f, suspects = 0.0f;
    float4 centre = sample_start == 0 ? (float4)(0.0f) : shift[i]; /* w: 1 once a sample set it */
    for (uint k = sample_start; k < sample_start + sample_count; ++k) {
        float3 d = camera_sample_direction(cam, q, seed, k);
        int suspect = 0;
        float3 L = trace_path(&s, camera_center(cam), d, seed, (uint)q.w, k, &suspect, 0, 0);
        suspects += (float)suspect;
        if (!all_finite3(L)) {
            dropped += 1.0f;
            continue;
        }
        if (centre.w == 0.0f)
            centre = (float4)(L, 1.0f);
        float3 x = L - centre.xyz;
        sum += x;
        sum_sq += x * x;
    }
    shift[i] = centre;
    accum[i] += (float4)(sum, dropped);
    accum_sq[i] += (float4)(sum_sq, suspects);
}

/* Ground-truth buffers through pixel centres: depth along the optical axis (inf on a miss),
 * world normal facing the camera, UV, instance id (0 on a miss), original triangle (-1). */
kernel void primary_aovs(SCENE_PARAMS, global const CameraData* cameras,
                         global const int4* requests, int num_requests, global float* depth,
                         global float4* normal, global float2* uv, global int* instance,
                         global int* triangle)
{
    int i = get_global_id(0);
    if (i >= num_requests)
        return;
    SCENE_INIT(s);
    int4 q = requests[i];
    global const CameraData* cam = cameras + q.x;
    float3 d = camera_direction(cam, (float)q.y + 0.5f, (float)q.z + 0.5f);
    Ray ray = make_ray(camera_center(cam), d);
    Hit hit = bvh_closest_hit(&s, &ray, RAY_TMAX, -1);
    if (hit.slot < 0) {
        depth[i] = INFINITY;
        normal[i] = (float4)(0.0f);
        uv[i] = (float2)(0.0f);
        instance[i] = 0;
        triangle[i] = -1;
        return;
    }
    SurfacePoint sp = surface_point(&s, &hit, d);
    depth[i] = camera_depth(cam, d, hit.t);
    normal[i] = (float4)(sp.n, 0.0f);
    uv[i] = sp.uv;
    instance[i] = s.tri_instance[hit.slot];
    triangle[i] = s.tri_id[hit.slot];
}
