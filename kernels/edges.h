#line 2 "edges.h"
/* Sampling points on the silhouette edges of the image (Li et al. 2018, "Differentiable Monte
 * Carlo Ray Tracing through Edge Sampling", section 4.1, primary visibility). The host
 * (render/silhouette.py, edge_candidates) lists the edges where the integrand may jump: mesh
 * boundaries, silhouettes (one face towards the camera, one away) and edges between two labels,
 * clipped to the near plane and to the image. Each comes as its two 3D end points (xyz, camera
 * z) and their pixels; a point is drawn with probability proportional to projected length. */
#ifndef INVRENDER_EDGES_H
#define INVRENDER_EDGES_H

typedef struct {
    float2 y;   /* pixel coordinates of the point */
    float2 n;   /* unit normal of the projected edge: the "+" side is y + eps n */
    float3 x;   /* the world point on the edge that projects to y */
    int part;   /* the part the edge belongs to (its velocity field, pose.h) */
} EdgeSample;

/* First edge whose inclusive cdf exceeds u. */
inline int pick_edge(global const float* cdf, int n, float u)
{
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (cdf[mid] > u)
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

/* The point at screen fraction a of edge e: uniform in pixel length along the projected edge.
 * Its 3D point by perspective-correct interpolation: 1/z is linear in screen space. */
inline EdgeSample sample_edge(global const float4* edge_a, global const float4* edge_b,
                              global const float4* edge_pixels, global const int* edge_part,
                              global const float* cdf, int num_edges, float u_edge, float a)
{
    int e = pick_edge(cdf, num_edges, u_edge);
    float4 A = edge_a[e], B = edge_b[e], Y = edge_pixels[e];
    EdgeSample s;
    s.y = mix(Y.xy, Y.zw, a);
    float2 t = normalize(Y.zw - Y.xy);
    s.n = (float2)(-t.y, t.x);
    float b = a * A.w / ((1.0f - a) * B.w + a * A.w);
    s.x = mix(A.xyz, B.xyz, b);
    s.part = edge_part[e];
    return s;
}

#endif
