#line 2 "traversal.cl"
/* Closest-hit traversal alone, for `invrender bench traversal` (workflow/invrender/bench/
 * traversal.py): camera rays, one cosine-sampled bounce from each hit (what a B = 1 render
 * traces), and the closest hits of a batch of such rays, without shading. With -D BVH_STATS
 * bvh_closest_hit counts the nodes and triangles each ray visits. */
#include "common.h"
#include "scene_data.h"
#include "intersect.h"
#include "bvh.h"
#include "camera.h"
#include "rng.h"

/* Ray i: pixel i % (W H), jittered with (seed, i). */
kernel void camera_rays(global const CameraData* cam, ulong seed, global float4* origin,
                        global float4* direction)
{
    int i = get_global_id(0), pixel = i % (cam->width * cam->height);
    float4 u = rng_uniform4(seed, (uint)i, 0u, 0u, RNG_BLOCK_CAMERA);
    float px = (float)(pixel % cam->width) + u.x, py = (float)(pixel / cam->width) + u.y;
    origin[i] = (float4)(camera_center(cam), as_float(-1));
    direction[i] = (float4)(camera_direction(cam, px, py), 0.0f);
}

/* origin.w holds the triangle slot to skip (as int bits); out = (t, b1, b2, slot as int bits). */
kernel void closest_hits(SCENE_PARAMS, global const float4* origin, global const float4* direction,
                         global float4* out
#ifdef BVH_STATS
                         , global int2* visits
#endif
)
{
    int i = get_global_id(0);
    SCENE_INIT(s);
    float4 o = origin[i];
    Ray r = make_ray(o.xyz, direction[i].xyz);
    Hit h = bvh_closest_hit(&s, &r, RAY_TMAX, as_int(o.w));
    out[i] = (float4)(h.t, h.b1, h.b2, as_float(h.slot));
#ifdef BVH_STATS
    visits[i] = (int2)(h.nodes, h.tris);
#endif
}

/* From each hit a cosine-distributed direction about the geometric normal on the side the ray
 * came from, leaving from the offset hit point and skipping its triangle (as integrator.h).
 * A miss gives a ray with direction 0, which the host drops. */
kernel void bounce_rays(SCENE_PARAMS, global const float4* origin, global const float4* direction,
                        global const float4* hits, ulong seed, global float4* origin_out,
                        global float4* direction_out)
{
    int i = get_global_id(0);
    SCENE_INIT(s);
    float4 h = hits[i];
    int slot = as_int(h.w);
    if (slot < 0) {
        direction_out[i] = (float4)(0.0f);
        return;
    }
    float3 v0 = tri_vertex(s.tri_v, slot, 0), v1 = tri_vertex(s.tri_v, slot, 1), v2 = tri_vertex(s.tri_v, slot, 2);
    float3 d = direction[i].xyz, p = (1.0f - h.y - h.z) * v0 + h.y * v1 + h.z * v2;
    float3 n = normalize(cross(v1 - v0, v2 - v0));
    n = dot(n, d) > 0.0f ? -n : n;
    float4 u = rng_uniform4(seed, (uint)i, 0u, 1u, RNG_BLOCK_SCATTER);
    float3 t = normalize(cross(fabs(n.x) > 0.5f ? (float3)(0.0f, 1.0f, 0.0f) : (float3)(1.0f, 0.0f, 0.0f), n));
    float3 b = cross(n, t);
    float r = sqrt(u.x), phi = 2.0f * M_PI_F * u.y;
    float3 wi = normalize(r * cos(phi) * t + r * sin(phi) * b + sqrt(fmax(0.0f, 1.0f - u.x)) * n);
    origin_out[i] = (float4)(offset_ray_origin(p, n), as_float(slot));
    direction_out[i] = (float4)(wi, 0.0f);
}
