#line 2 "silhouette.cl"
/* Label coverage and depth images of posed meshes, and their derivatives w.r.t. each part's
 * pose (render/silhouette.py). Only primary visibility: the first hit of each camera ray.
 * I = integral over a pixel of f(y), f = (one-hot label, camera-space depth) of the first hit,
 * (nothing, 0) on a miss. dI/dtheta = interior term (the depth of a hit moves with its
 * triangle) + boundary term (edges.h: the jump of f across an edge times its normal velocity),
 * both weighted by the adjoint images dL/dmasks and dL/ddepth, summed per part and parameter. */
#include "common.h"
#include "scene_data.h"
#include "intersect.h"
#include "bvh.h"
#include "camera.h"
#include "rng.h"
#include "pose.h"
#include "projection.h"
#include "edges.h"

#define SILHOUETTE_BVH global const float8 *bvh_bounds, global const int8 *bvh_children, \
                       global const float8 *bvh_leaves

/* A SceneData with only the BVH set: closest-hit traversal reads nothing else. */
#define SILHOUETTE_ZERO_BUFFER(type, name) s.name = 0;
#define SILHOUETTE_ZERO_VALUE(type, name) s.name = 0;
inline SceneData geometry_only(SILHOUETTE_BVH)
{
    SceneData s;
    SCENE_DATA(SILHOUETTE_ZERO_BUFFER, SILHOUETTE_ZERO_VALUE, SCENE_NOTHING)
    s.proposal = 0;
    s.bvh_bounds = bvh_bounds;
    s.bvh_children = bvh_children;
    s.bvh_leaves = bvh_leaves;
    return s;
}

/* The first hit through pixel point (px, py): its label (-1 on a miss) and camera depth. */
typedef struct {
    Hit hit;
    float3 d;
    int label;
    float depth;
} Primary;

inline Primary trace_primary(const SceneData* s, global const CameraData* cam, global const int* slot_label,
                             float px, float py)
{
    Primary p;
    p.d = camera_direction(cam, px, py);
    Ray r = make_ray(camera_center(cam), p.d);
    p.hit = bvh_closest_hit(s, &r, RAY_TMAX, -1);
    p.label = p.hit.slot >= 0 ? slot_label[p.hit.slot] : -1;
    p.depth = p.hit.slot >= 0 ? camera_depth(cam, p.d, p.hit.t) : 0.0f;
    return p;
}

/* Sample k of spp in pixel (x, y): stratified on the largest square grid that fits in spp,
 * uniform for the rest. */
inline float2 pixel_sample(int x, int y, int k, int spp, ulong seed, int pixel)
{
    float4 u = rng_uniform4(seed, (uint)pixel, (uint)k, 0u, RNG_BLOCK_CAMERA);
    int n = (int)sqrt((float)spp);
    while ((n + 1) * (n + 1) <= spp)
        ++n;
    while (n * n > spp)
        --n;
    if (k < n * n)
        u.xy = ((float2)((float)(k % n), (float)(k / n)) + u.xy) / (float)n;
    return (float2)((float)x + u.x, (float)y + u.y);
}

inline float label_adjoint(global const float* adj_masks, int num_labels, int label, int pixel, int num_pixels)
{
    return label >= 0 && label < num_labels ? adj_masks[label * num_pixels + pixel] : 0.0f;
}

/* One work-item per pixel: masks (L, H, W) += label coverage, depth (H, W) = mean depth. */
kernel void silhouette_forward(SILHOUETTE_BVH, global const int* slot_label, global const CameraData* cam,
                               int spp, ulong seed, int num_labels, global float* masks, global float* depth)
{
    int pixel = get_global_id(0), w = cam->width, num_pixels = cam->width * cam->height;
    if (pixel >= num_pixels)
        return;
    SceneData s = geometry_only(bvh_bounds, bvh_children, bvh_leaves);
    float weight = 1.0f / (float)spp, depth_sum = 0.0f;
    for (int k = 0; k < spp; ++k) {
        float2 y = pixel_sample(pixel % w, pixel / w, k, spp, seed, pixel);
        Primary p = trace_primary(&s, cam, slot_label, y.x, y.y);
        if (p.label >= 0 && p.label < num_labels)
            masks[p.label * num_pixels + pixel] += weight;
        depth_sum += p.depth;
    }
    depth[pixel] = depth_sum * weight;
}

/* Interior term, one work-item per camera ray (ray = pixel spp + k, the forward's rays): the
 * hit point rides on its triangle's plane, so along the fixed ray dt = n.V / n.d and the depth
 * t (forward . d) moves with it; labels do not change inside a triangle. Writes the ray's
 * part (-1: none) and its 9 derivatives weighted by dL/ddepth / spp. */
kernel void silhouette_interior(SILHOUETTE_BVH, global const int* slot_label, global const int* slot_part,
                                global const float4* tri_v, global const CameraData* cam,
                                global const float4* velocity, int spp, ulong seed, global const float* adj_depth,
                                int first_ray, int num_rays, global int* out_part, global float* out_grad)
{
    int i = get_global_id(0);
    if (i >= num_rays)
        return;
    int ray = first_ray + i, pixel = ray / spp, k = ray % spp, w = cam->width;
    SceneData s = geometry_only(bvh_bounds, bvh_children, bvh_leaves);
    float2 y = pixel_sample(pixel % w, pixel / w, k, spp, seed, pixel);
    Primary p = trace_primary(&s, cam, slot_label, y.x, y.y);
    float adjoint = adj_depth[pixel] / (float)spp;
    out_part[i] = p.hit.slot >= 0 && adjoint != 0.0f ? slot_part[p.hit.slot] : -1;
    if (out_part[i] < 0)
        return;
    float3 v0 = tri_vertex(tri_v, p.hit.slot, 0), v1 = tri_vertex(tri_v, p.hit.slot, 1);
    float3 n = cross(v1 - v0, tri_vertex(tri_v, p.hit.slot, 2) - v0);
    float3 x = camera_center(cam) + p.hit.t * p.d;
    float scale = adjoint * (p.depth / p.hit.t) / dot(n, p.d); /* dL/ddepth (forward . d) / n.d */
    for (int j = 0; j < POSE_PARAMS; ++j)
        out_grad[POSE_PARAMS * i + j] = scale * dot(n, pose_velocity(velocity, out_part[i], j, x));
}

/* Boundary term, one work-item per edge sample: a point on a listed edge, drawn by projected
 * length (pdf 1 / total_length), counts where the edge is seen (nothing closer along its ray).
 * Moving the edge by delta along n turns a strip of the "+" side into the "-" side, so
 * dI = (f(-) - f(+)) (n . dy/dtheta) per unit length; f on either side from a ray offset by
 * eps pixels. Writes the sample's part (-1: none) and its 9 adjoint-weighted derivatives,
 * already divided by pdf and the number of samples. */
kernel void silhouette_boundary(SILHOUETTE_BVH, global const int* slot_label, global const CameraData* cam,
                                global const float4* velocity, global const float4* edge_a,
                                global const float4* edge_b, global const float4* edge_pixels,
                                global const int* edge_part, global const float* edge_cdf, int num_edges,
                                float total_length, int num_samples, float eps, ulong seed, int num_labels,
                                global const float* adj_masks, global const float* adj_depth, int first_sample,
                                int count, global int* out_part, global float* out_grad)
{
    int i = get_global_id(0);
    if (i >= count)
        return;
    out_part[i] = -1;
    float4 u = rng_uniform4(seed, (uint)(first_sample + i), 0u, 0u, RNG_BLOCK_CAMERA);
    EdgeSample e = sample_edge(edge_a, edge_b, edge_pixels, edge_part, edge_cdf, num_edges, u.x, u.y);
    int px = (int)floor(e.y.x), py = (int)floor(e.y.y);
    if (px < 0 || py < 0 || px >= cam->width || py >= cam->height)
        return;
    int pixel = py * cam->width + px, num_pixels = cam->width * cam->height;
    SceneData s = geometry_only(bvh_bounds, bvh_children, bvh_leaves);
    /* seen: nothing along the ray through y before the edge point (relative slack for float) */
    float3 c = camera_center(cam);
    Ray r = make_ray(c, camera_direction(cam, e.y.x, e.y.y));
    if (bvh_closest_hit(&s, &r, 0.999f * length(e.x - c), -1).slot >= 0)
        return;
    Primary minus = trace_primary(&s, cam, slot_label, e.y.x - eps * e.n.x, e.y.y - eps * e.n.y);
    Primary plus = trace_primary(&s, cam, slot_label, e.y.x + eps * e.n.x, e.y.y + eps * e.n.y);
    float jump = label_adjoint(adj_masks, num_labels, minus.label, pixel, num_pixels) -
                 label_adjoint(adj_masks, num_labels, plus.label, pixel, num_pixels) +
                 adj_depth[pixel] * (minus.depth - plus.depth);
    if (jump == 0.0f)
        return;
    out_part[i] = e.part;
    float weight = jump * total_length / (float)num_samples;
    for (int j = 0; j < POSE_PARAMS; ++j)
        out_grad[POSE_PARAMS * i + j] =
            weight * dot(e.n, project_velocity(cam, e.x, pose_velocity(velocity, e.part, j, e.x)));
}
