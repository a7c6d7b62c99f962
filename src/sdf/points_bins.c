/*
 * Points binned into cubic cells for neighbour searches (the point-cloud
 * surface and its orientation): a counting sort by cell, and a hash table
 * from a cell's key to its run of points.
 */
#include "sdf_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define PTS_KEY_BITS 21 /* per axis in a cell key */

static uint64_t hash_key(uint64_t k)
{
    k += 0x9e3779b97f4a7c15ull;
    k = (k ^ (k >> 30)) * 0xbf58476d1ce4e5b9ull;
    k = (k ^ (k >> 27)) * 0x94d049bb133111ebull;
    return k ^ (k >> 31);
}

/* The key of cell (i, j, k); UINT64_MAX outside the keyed range. */
uint64_t hv__cell_key(long i, long j, long k)
{
    const long lim = 1L << PTS_KEY_BITS;
    if (i < 0 || j < 0 || k < 0 || i >= lim || j >= lim || k >= lim)
        return UINT64_MAX;
    return (uint64_t)i | (uint64_t)j << PTS_KEY_BITS | (uint64_t)k << (2 * PTS_KEY_BITS);
}

void hv__cell_of(const pt_bins *B, const double *x, long c[3])
{
    for (int a = 0; a < 3; a++)
        c[a] = (long)floor((x[a] - B->lo[a]) / B->c);
}

void hv__bins_free(pt_bins *B)
{
    free(B->order);
    free(B->sx);
    free(B->keys);
    free(B->start);
    free(B->len);
}

/* The table slot of key: where it is, or the empty one where it goes. */
static size_t bins_slot(const pt_bins *B, uint64_t key)
{
    size_t s = hash_key(key) & B->mask;
    while (B->keys[s] != UINT64_MAX && B->keys[s] != key)
        s = (s + 1) & B->mask;
    return s;
}

/* Makes the table of B cap slots (a power of two) and moves its cells
 * over; -1 when out of memory. */
static int bins_resize(pt_bins *B, size_t cap)
{
    pt_bins N = *B;
    N.mask = cap - 1;
    N.keys = malloc(cap * sizeof *N.keys);
    N.len = calloc(cap, sizeof *N.len);
    if (!N.keys || !N.len) {
        free(N.keys);
        free(N.len);
        return -1;
    }
    memset(N.keys, 0xff, cap * sizeof *N.keys);
    for (size_t t = 0; B->keys && t <= B->mask; t++)
        if (B->keys[t] != UINT64_MAX) {
            size_t u = bins_slot(&N, B->keys[t]);
            N.keys[u] = B->keys[t];
            N.len[u] = B->len[t];
        }
    free(B->keys);
    free(B->len);
    *B = N;
    return 0;
}

/* Counts the points of each cell (keys[i]: point i's cell) into the
 * table, growing it to stay at most half full; the number of cells. */
static size_t bins_count(pt_bins *B, const uint64_t *keys, size_t n)
{
    size_t cells = 0;
    if (bins_resize(B, 1024))
        return SIZE_MAX;
    for (size_t i = 0; i < n; i++) {
        size_t t = bins_slot(B, keys[i]);
        if (B->keys[t] == UINT64_MAX) {
            B->keys[t] = keys[i];
            if (2 * ++cells > B->mask && bins_resize(B, 2 * (B->mask + 1)))
                return SIZE_MAX;
            t = bins_slot(B, keys[i]);
        }
        B->len[t]++;
    }
    return cells;
}

/* The run of points in cell key: *len points from order + *start. */
int hv__bins_find(const pt_bins *B, uint64_t key, uint32_t *start, uint32_t *len)
{
    if (key == UINT64_MAX)
        return 0;
    for (size_t s = hash_key(key) & B->mask;; s = (s + 1) & B->mask) {
        if (B->keys[s] == UINT64_MAX)
            return 0;
        if (B->keys[s] == key) {
            *start = B->start[s];
            *len = B->len[s];
            return 1;
        }
    }
}

/* Bins the n points xyz into cells of side c from lo: a counting sort
 * through the table, so each cell's points stay in input order. */
hv_status hv__bins_build(pt_bins *B, const double *xyz, size_t n, const double lo[3], double c,
                         size_t *cells)
{
    memset(B, 0, sizeof *B);
    memcpy(B->lo, lo, sizeof B->lo);
    B->c = c;
    uint64_t *keys = malloc(n * sizeof *keys);
    B->order = malloc(n * sizeof *B->order);
    if (!keys || !B->order) {
        free(keys);
        return hv__error(HV_ERR_NOMEM, "points: out of memory binning %zu points", n);
    }
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < n; i++) {
        long q[3];
        hv__cell_of(B, xyz + 3 * i, q);
        for (int a = 0; a < 3; a++) /* a point past the keyed range joins its edge cell */
            q[a] = q[a] < 0 ? 0 : q[a] >= (1L << PTS_KEY_BITS) ? (1L << PTS_KEY_BITS) - 1 : q[a];
        keys[i] = hv__cell_key(q[0], q[1], q[2]);
    }
    *cells = bins_count(B, keys, n);
    B->start = *cells != SIZE_MAX ? malloc((B->mask + 1) * sizeof *B->start) : NULL;
    if (!B->start) {
        free(keys);
        return hv__error(HV_ERR_NOMEM, "points: out of memory for the cells of %zu points", n);
    }
    uint32_t at = 0;
    for (size_t t = 0; t <= B->mask; t++) {
        B->start[t] = at;
        at += B->len[t];
    }
    for (size_t i = 0; i < n; i++) /* start[t] walks to the end of its run */
        B->order[B->start[bins_slot(B, keys[i])]++] = (uint32_t)i;
    for (size_t t = 0; t <= B->mask; t++)
        B->start[t] -= B->len[t];
    free(keys);
    if (!(B->sx = malloc(3 * n * sizeof *B->sx)))
        return hv__error(HV_ERR_NOMEM, "points: out of memory binning %zu points", n);
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < n; i++)
        for (int a = 0; a < 3; a++)
            B->sx[3 * i + a] = (float)(xyz[3 * (size_t)B->order[i] + a] - lo[a]);
    return HV_OK;
}

/* Steps d through the cube [-r, r]^3, x fastest; 0 past its end. */
static int cube_step(long d[3], long r)
{
    for (int a = 0; a < 3; a++) {
        if (d[a] < r) {
            d[a]++;
            return 1;
        }
        d[a] = -r;
    }
    return 0;
}

/* Loads the next cell of the ring that has points; 0 when none is left. */
static int ring_cell(const pt_bins *B, ring_iter *it)
{
    do {
        if (!cube_step(it->d, it->r))
            return 0;
        if (labs(it->d[0]) != it->r && labs(it->d[1]) != it->r && labs(it->d[2]) != it->r)
            continue;
        it->m = 0;
    } while (!hv__bins_find(
        B, hv__cell_key(it->q[0] + it->d[0], it->q[1] + it->d[1], it->q[2] + it->d[2]), &it->s,
        &it->len));
    return 1;
}

void hv__ring_first(ring_iter *it, const long q[3], long r)
{
    memcpy(it->q, q, sizeof it->q);
    it->r = r;
    it->d[0] = -r - 1; /* cube_step's first step lands on (-r, -r, -r) */
    it->d[1] = it->d[2] = -r;
    it->len = it->m = 0;
}

int hv__ring_next(const pt_bins *B, ring_iter *it, uint32_t *j)
{
    while (it->m >= it->len)
        if (!ring_cell(B, it))
            return 0;
    *j = B->order[it->s + it->m++];
    return 1;
}

/* The cell of table slot t. */
void hv__slot_cell(const pt_bins *B, size_t t, long q[3])
{
    const uint64_t key = B->keys[t], mask = (1u << PTS_KEY_BITS) - 1;
    q[0] = (long)(key & mask);
    q[1] = (long)(key >> PTS_KEY_BITS & mask);
    q[2] = (long)(key >> (2 * PTS_KEY_BITS));
}
