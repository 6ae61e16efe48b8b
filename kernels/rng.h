#line 2 "rng.h"
/* Counter-based random numbers: Philox-4x32-10 (Salmon et al. 2011, "Parallel random numbers:
 * as easy as 1, 2, 3"). A render is a pure function of its inputs and its seed: the numbers a
 * path uses depend only on (seed, ray id, sample, bounce, block), never on scheduling.
 * Reference: workflow/invrender/render/rng.py (tested bit for bit). */
#ifndef INVRENDER_RNG_H
#define INVRENDER_RNG_H

/* Blocks of four numbers within one (ray, sample, bounce). */
#define RNG_BLOCK_SCATTER 0u /* strategy choice + 3 numbers for the chosen strategy */
#define RNG_BLOCK_CAMERA 1u  /* pixel jitter (bounce 0) */
#define RNG_BLOCK_LIGHT 2u   /* light choice + 3 numbers for the light sample (nee.h) */
#define RNG_BLOCK_ROULETTE 3u /* Russian roulette (x), its own so survival is independent of wi */

inline uint4 philox4x32_10(uint4 ctr, uint2 key)
{
    const uint M0 = 0xD2511F53u, M1 = 0xCD9E8D57u, W0 = 0x9E3779B9u, W1 = 0xBB67AE85u;
    for (int round = 0; round < 10; ++round) {
        /* the high words through a 64-bit product, not mul_hi: PoCL calls mul_hi out of line
         * (15 % of a one-bounce render); the same bits */
        ulong p0 = (ulong)M0 * ctr.x, p1 = (ulong)M1 * ctr.z;
        uint hi0 = (uint)(p0 >> 32), lo0 = (uint)p0;
        uint hi1 = (uint)(p1 >> 32), lo1 = (uint)p1;
        ctr = (uint4)(hi1 ^ ctr.y ^ key.x, lo1, hi0 ^ ctr.w ^ key.y, lo0);
        key += (uint2)(W0, W1);
    }
    return ctr;
}

/* Four uniform floats in [0, 1): the top 24 bits of each word, so 1.0 is never returned. */
inline float4 rng_uniform4(ulong seed, uint ray, uint sample, uint bounce, uint block)
{
    uint4 bits = philox4x32_10((uint4)(ray, sample, bounce, block),
                               (uint2)((uint)(seed & 0xffffffffUL), (uint)(seed >> 32)));
    return convert_float4(bits >> 8) * (1.0f / 16777216.0f);
}

#endif
