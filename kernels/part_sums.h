#line 2 "part_sums.h"
/* Sums of per-sample derivatives by part, in a work-group's local memory: each sample adds its
 * POSE_PARAMS derivatives to the row of the part it moves with (a sample touches one part),
 * and each group writes its table, num_parts x POSE_PARAMS floats, for the host to add up.
 * No atomics: per round every work-item leaves its sample in local memory and POSE_PARAMS
 * work-items add them up, one column each. The group size is PART_SUMS_GROUP (the host's). */
#ifndef INVRENDER_PART_SUMS_H
#define INVRENDER_PART_SUMS_H

#include "pose.h"

#define PART_SUMS_GROUP 64

typedef struct {
    int part; /* -1: the sample adds nothing */
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

/* Every work-item of the group calls this once per round, with its sample's derivatives. */
inline void part_sums_add(local float* table, local int* parts, local float* values, PartDerivatives r)
{
    int lid = get_local_id(0), n = get_local_size(0);
    parts[lid] = r.part;
    for (int j = 0; j < POSE_PARAMS; ++j)
        values[POSE_PARAMS * lid + j] = r.d[j];
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid < POSE_PARAMS)
        for (int k = 0; k < n; ++k)
            if (parts[k] >= 0)
                table[POSE_PARAMS * parts[k] + lid] += values[POSE_PARAMS * k + lid];
    barrier(CLK_LOCAL_MEM_FENCE);
}

inline void part_sums_write(local const float* table, int num_parts, global float* out)
{
    global float* mine = out + get_group_id(0) * num_parts * POSE_PARAMS;
    for (int k = get_local_id(0); k < num_parts * POSE_PARAMS; k += get_local_size(0))
        mine[k] = table[k];
}

#endif
