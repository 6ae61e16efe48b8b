#line 2 "part_sums.h"
/* Sums of per-sample derivatives by part, in a work-group's local memory: each sample adds its
 * POSE_PARAMS derivatives to the row of the part it moves with (a sample touches one part), and
 * each group writes its table, num_parts x POSE_PARAMS floats, for the host to add up.
 * A work-item takes consecutive samples (the rays of one pixel, mostly one part), sums them in
 * private while the part stays the same and adds that sum to the table when it changes, with a
 * compare-and-swap float add on local memory (core OpenCL 1.1 atomics, no extension). No
 * barrier inside the sample loop: PoCL runs a group's work-items one after another between
 * barriers, and a barrier in a loop makes it save every work-item's state each round. */
#ifndef INVRENDER_PART_SUMS_H
#define INVRENDER_PART_SUMS_H

#include "pose.h"

typedef struct {
    int part; /* -1: nothing */
    float d[POSE_PARAMS];
} PartDerivatives;

inline PartDerivatives no_derivatives(void)
{
    PartDerivatives r;
    r.part = -1;
    for (int j = 0; j < POSE_PARAMS; ++j)
        r.d[j] = 0.0f;
    return r;
}

inline void part_sums_clear(local float* table, int num_parts)
{
    for (int k = get_local_id(0); k < num_parts * POSE_PARAMS; k += get_local_size(0))
        table[k] = 0.0f;
    barrier(CLK_LOCAL_MEM_FENCE);
}

inline void local_float_add(volatile local float* p, float v)
{
    union {
        uint u;
        float f;
    } seen, want;
    do {
        seen.f = *p;
        want.f = seen.f + v;
    } while (atomic_cmpxchg((volatile local uint*)p, seen.u, want.u) != seen.u);
}

inline void part_sums_flush(local float* table, PartDerivatives* sum)
{
    if (sum->part >= 0)
        for (int j = 0; j < POSE_PARAMS; ++j)
            local_float_add(table + POSE_PARAMS * sum->part + j, sum->d[j]);
    *sum = no_derivatives();
}

inline void part_sums_add(local float* table, PartDerivatives* sum, PartDerivatives r)
{
    if (r.part < 0)
        return;
    if (r.part != sum->part) {
        part_sums_flush(table, sum);
        sum->part = r.part;
    }
    for (int j = 0; j < POSE_PARAMS; ++j)
        sum->d[j] += r.d[j];
}

/* After every work-item's last flush. */
inline void part_sums_write(local const float* table, int num_parts, global float* out)
{
    barrier(CLK_LOCAL_MEM_FENCE);
    global float* mine = out + get_group_id(0) * num_parts * POSE_PARAMS;
    for (int k = get_local_id(0); k < num_parts * POSE_PARAMS; k += get_local_size(0))
        mine[k] = table[k];
}

#endif
