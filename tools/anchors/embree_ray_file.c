// Embree 3 traces the rays of a mipray ray file (`mipray export --rays`), class by class,
// on ONE thread, with its single-ray API and its 4-, 8- and 16-wide packet APIs, on the
// refittable build (what a dynamic scene gets), the static high-quality build, and that
// build in robust mode (RTC_SCENE_FLAG_ROBUST: robust traversal and no optimisation that
// loses accuracy, the nearest Embree comes to mipray's padded boxes and watertight
// triangle test); and checks its answers against the file's.
//
// build:  cc -O3 -march=native -o embree_ray_file embree_ray_file.c -lembree3 -lm
// usage:  embree_ray_file FRAME.obj RAYS.bin WIDTH [REPS [ONLY]]
//   FRAME.obj: the frame's exported mesh (its face order is the file's triangle index).
//   RAYS.bin:  MIPRAYS1 records (format: docs/src/reference/ray-file.md).
//   WIDTH:     the image width, to group rays into pixel blocks for packets.
//   REPS:      timed samples of each (build, class, API); a sample is one pass over the
//              class's rays, or several back to back until MIN_SAMPLE_MS have gone by.
//   ONLY:      BUILD:CLASS:API (e.g. refit:shadow:16): build that scene alone and trace that
//              one combination, one pass a sample, so that an instruction count of the
//              whole process (instructions_side_by_side.sh) holds nothing else that grows
//              with REPS.
//
// APIs: "1" traces the class's rays one at a time in file order. Packets of N lanes take
// the class's rays grouped by pixel block (2x2 for 4, 4x2 for 8, 4x4 for 16) and, within a
// block, by rank (a pixel's first ray of the class, its second, ...: rays of one bounce
// depth go together), with RTC_INTERSECT_CONTEXT_FLAG_COHERENT; the last packet of a
// (block, rank) group is padded with masked-off lanes. Packets are filled before the clock
// starts.
// Output, one line per (build, class, API):
//   ray BUILD CLASS API RAYS HITS BEST_MRAYS MEDIAN_MRAYS AGREE
// HITS: hit (closest) or blocked (shadow); AGREE: answers equal to the file's (closest: the
// same face, or both miss; shadow: the same blocked flag). Closest-hit answers can differ on
// exact ties (mipray gives a tie to the lowest source triangle) and on edges (Embree's
// triangle test is not watertight).
#include <embree3/rtcore.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

// The least time one timed sample takes (see the timing loop in main).
#define MIN_SAMPLE_MS 20.0

static double now_ms(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static void *xmalloc(size_t n) {
    void *p = malloc(n ? n : 1);
    if (!p) { fprintf(stderr, "out of memory\n"); exit(2); }
    return p;
}

// ---------------------------------------------------------------- mesh: positions, faces
typedef struct { float *v; unsigned *idx; size_t nv, nt, cv, ct; } Mesh;

static int load_obj(const char *path, Mesh *m) {
    FILE *f = fopen(path, "r");
    if (!f) { perror(path); return -1; }
    memset(m, 0, sizeof *m);
    char line[4096];
    while (fgets(line, sizeof line, f)) {
        if (line[0] == 'v' && line[1] == ' ') {
            if (m->nv == m->cv) { m->cv = m->cv ? 2 * m->cv : 1 << 16; m->v = realloc(m->v, m->cv * 12); }
            char *p = line + 2;
            for (int k = 0; k < 3; k++) m->v[3 * m->nv + k] = strtof(p, &p);
            m->nv++;
        } else if (line[0] == 'f' && line[1] == ' ') {
            long vi[3];
            int n = 0;
            char *p = line + 2;
            while (*p && n < 3) {
                while (*p == ' ' || *p == '\t') p++;
                if (!*p || *p == '\n' || *p == '\r') break;
                long a = strtol(p, &p, 10);
                vi[n++] = a < 0 ? (long)m->nv + a : a - 1;
                while (*p && *p != ' ' && *p != '\t' && *p != '\n' && *p != '\r') p++;
            }
            if (n != 3) { fprintf(stderr, "%s: a face that is not a triangle\n", path); return -1; }
            if (m->nt == m->ct) { m->ct = m->ct ? 2 * m->ct : 1 << 16; m->idx = realloc(m->idx, m->ct * 12); }
            for (int j = 0; j < 3; j++) m->idx[3 * m->nt + j] = (unsigned)vi[j];
            m->nt++;
        }
    }
    fclose(f);
    return 0;
}

// ---------------------------------------------------------------- the ray file
typedef struct { float o[3], d[3], tmin, tmax; uint32_t cls, pixel, result; float t; } Rec;
static uint32_t *rank_of;  // per record: how many earlier records share its class and pixel
static Rec *records;

static Rec *load_rays(const char *path, size_t *count) {
    FILE *f = fopen(path, "rb");
    if (!f) { perror(path); return NULL; }
    char magic[8];
    uint64_t n;
    if (fread(magic, 1, 8, f) != 8 || memcmp(magic, "MIPRAYS1", 8) || fread(&n, 8, 1, f) != 1) {
        fprintf(stderr, "%s: not a MIPRAYS1 file\n", path);
        return NULL;
    }
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    if ((uint64_t)size != 16 + n * 48) { fprintf(stderr, "%s: length disagrees with the count\n", path); return NULL; }
    fseek(f, 16, SEEK_SET);
    Rec *r = xmalloc(n * sizeof(Rec));
    for (uint64_t i = 0; i < n; i++)
        if (fread(&r[i], 48, 1, f) != 1) { fprintf(stderr, "%s: short read\n", path); return NULL; }
    fclose(f);
    *count = n;
    return r;
}

// ---------------------------------------------------------------- Embree scenes
// kind: 0 refittable, 1 static high quality, 2 static high quality in robust mode.
static RTCScene make_scene(RTCDevice dev, const Mesh *m, int kind) {
    RTCScene s = rtcNewScene(dev);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (kind == 0) {
        rtcSetSceneBuildQuality(s, RTC_BUILD_QUALITY_LOW);
        rtcSetSceneFlags(s, RTC_SCENE_FLAG_DYNAMIC);
        rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_REFIT);
    } else {
        rtcSetSceneBuildQuality(s, RTC_BUILD_QUALITY_HIGH);
        rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_HIGH);
        if (kind == 2) rtcSetSceneFlags(s, RTC_SCENE_FLAG_ROBUST);
    }
    float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, m->nv);
    memcpy(vb, m->v, m->nv * 12);
    unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, m->nt);
    memcpy(ib, m->idx, m->nt * 12);
    rtcCommitGeometry(g);
    rtcAttachGeometry(s, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(s);
    return s;
}

// ---------------------------------------------------------------- one class, prepared
typedef struct {
    size_t n;          // rays of the class
    Rec **ray;         // in file order
    int packets[3];    // packets of 4, 8, 16
    Rec **lane[3];     // packets[w] * width lanes, NULL where masked off
} Class;

static const int WIDTHS[3] = {4, 8, 16}, TILE_W[3] = {2, 4, 4};
static int W;

static uint64_t block_of(const Rec *r, int tw, int th) {
    uint32_t x = r->pixel % (uint32_t)W, y = r->pixel / (uint32_t)W;
    uint64_t block = (uint64_t)(y / th) * (uint64_t)((W + tw - 1) / tw) + x / tw;
    return (block << 20) | (rank_of[r - records] & 0xFFFFF);  // then by rank
}

static int cmp_block_tw, cmp_block_th;
static int cmp_rays(const void *a, const void *b) {
    const Rec *ra = *(Rec *const *)a, *rb = *(Rec *const *)b;
    uint64_t ba = block_of(ra, cmp_block_tw, cmp_block_th), bb = block_of(rb, cmp_block_tw, cmp_block_th);
    if (ba != bb) return ba < bb ? -1 : 1;
    return ra < rb ? -1 : ra > rb;  // file order within a block
}

static void prepare(Class *c, Rec *all, size_t count, uint32_t cls) {
    memset(c, 0, sizeof *c);
    for (size_t i = 0; i < count; i++) c->n += all[i].cls == cls;
    c->ray = xmalloc(c->n * sizeof(Rec *));
    size_t k = 0;
    for (size_t i = 0; i < count; i++) if (all[i].cls == cls) c->ray[k++] = &all[i];
    Rec **sorted = xmalloc(c->n * sizeof(Rec *));
    for (int w = 0; w < 3; w++) {
        int N = WIDTHS[w], tw = TILE_W[w], th = N / tw;
        memcpy(sorted, c->ray, c->n * sizeof(Rec *));
        cmp_block_tw = tw; cmp_block_th = th;
        qsort(sorted, c->n, sizeof(Rec *), cmp_rays);
        c->lane[w] = xmalloc((c->n + 1) * 16 * sizeof(Rec *) + 16 * sizeof(Rec *));
        int p = 0, fill = 0;
        for (size_t i = 0; i < c->n; i++) {
            if (fill > 0 && (fill == N || block_of(sorted[i], tw, th) != block_of(sorted[i - 1], tw, th))) {
                for (; fill < N; fill++) c->lane[w][p * N + fill] = NULL;
                p++; fill = 0;
            }
            c->lane[w][p * N + fill++] = sorted[i];
        }
        if (fill > 0) { for (; fill < N; fill++) c->lane[w][p * N + fill] = NULL; p++; }
        c->packets[w] = p;
    }
    free(sorted);
}

// ---------------------------------------------------------------- tracing
static inline void fill1(struct RTCRay *r, const Rec *x) {
    r->org_x = x->o[0]; r->org_y = x->o[1]; r->org_z = x->o[2];
    r->dir_x = x->d[0]; r->dir_y = x->d[1]; r->dir_z = x->d[2];
    r->tnear = x->tmin; r->tfar = x->tmax; r->mask = -1; r->flags = 0; r->time = 0.0f; r->id = 0;
}

static inline int agrees(const Rec *x, int shadow, int hit, unsigned prim) {
    if (shadow) return (x->result == 1) == hit;
    return hit ? x->result == prim : x->result == 0xFFFFFFFFu;
}

static long trace1(RTCScene s, const Class *c, int shadow, long *agree) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    long hits = 0, ok = 0;
    for (size_t i = 0; i < c->n; i++) {
        const Rec *x = c->ray[i];
        if (shadow) {
            _Alignas(16) struct RTCRay r;
            fill1(&r, x);
            rtcOccluded1(s, &ctx, &r);
            int hit = r.tfar < 0.0f;
            hits += hit; ok += agrees(x, 1, hit, 0);
        } else {
            _Alignas(16) struct RTCRayHit rh;
            fill1(&rh.ray, x);
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID; rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(s, &ctx, &rh);
            int hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
            hits += hit; ok += agrees(x, 0, hit, rh.hit.primID);
        }
    }
    *agree = ok;
    return hits;
}

#define PACKET_TRACE(NAME, N, RAYHIT, ISECT, OCCL, WI)                                            \
    static long NAME(RTCScene s, const Class *c, int shadow, long *agree) {                       \
        struct RTCIntersectContext ctx;                                                           \
        rtcInitIntersectContext(&ctx);                                                            \
        ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;                                          \
        long hits = 0, ok = 0;                                                                    \
        for (int p = 0; p < c->packets[WI]; p++) {                                                \
            Rec *const *lane = &c->lane[WI][p * N];                                               \
            _Alignas(64) int valid[N];                                                            \
            _Alignas(64) struct RAYHIT q;                                                         \
            for (int k = 0; k < N; k++) {                                                         \
                const Rec *x = lane[k] ? lane[k] : lane[0];                                       \
                valid[k] = lane[k] ? -1 : 0;                                                      \
                q.ray.org_x[k] = x->o[0]; q.ray.org_y[k] = x->o[1]; q.ray.org_z[k] = x->o[2];     \
                q.ray.dir_x[k] = x->d[0]; q.ray.dir_y[k] = x->d[1]; q.ray.dir_z[k] = x->d[2];     \
                q.ray.tnear[k] = x->tmin; q.ray.tfar[k] = x->tmax; q.ray.mask[k] = -1;            \
                q.ray.flags[k] = 0; q.ray.time[k] = 0.0f; q.ray.id[k] = (unsigned)k;              \
                q.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;                                        \
                q.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;                                     \
            }                                                                                     \
            if (shadow) {                                                                         \
                OCCL(valid, s, &ctx, &q.ray);                                                     \
                for (int k = 0; k < N; k++)                                                       \
                    if (valid[k]) { int h = q.ray.tfar[k] < 0.0f; hits += h; ok += agrees(lane[k], 1, h, 0); } \
            } else {                                                                              \
                ISECT(valid, s, &ctx, &q);                                                        \
                for (int k = 0; k < N; k++)                                                       \
                    if (valid[k]) {                                                               \
                        int h = q.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;                        \
                        hits += h; ok += agrees(lane[k], 0, h, q.hit.primID[k]);                  \
                    }                                                                             \
            }                                                                                     \
        }                                                                                         \
        *agree = ok;                                                                              \
        return hits;                                                                              \
    }
PACKET_TRACE(trace4, 4, RTCRayHit4, rtcIntersect4, rtcOccluded4, 0)
PACKET_TRACE(trace8, 8, RTCRayHit8, rtcIntersect8, rtcOccluded8, 1)
PACKET_TRACE(trace16, 16, RTCRayHit16, rtcIntersect16, rtcOccluded16, 2)

enum { APIS = 4 };
static const char *API_NAME[APIS] = {"1", "4", "8", "16"};
static long trace_api(int api, RTCScene s, const Class *c, int shadow, long *agree) {
    switch (api) {
    case 0: return trace1(s, c, shadow, agree);
    case 1: return trace4(s, c, shadow, agree);
    case 2: return trace8(s, c, shadow, agree);
    default: return trace16(s, c, shadow, agree);
    }
}

static int cmp_d(const void *a, const void *b) { double x = *(const double *)a, y = *(const double *)b; return (x > y) - (x < y); }

int main(int argc, char **argv) {
    if (argc < 4) { fprintf(stderr, "usage: %s FRAME.obj RAYS.bin WIDTH [REPS [ONLY]]\n", argv[0]); return 2; }
    Mesh m;
    if (load_obj(argv[1], &m)) return 2;
    size_t count;
    Rec *rays = load_rays(argv[2], &count);
    if (!rays) return 2;
    records = rays;
    rank_of = xmalloc(count * sizeof(uint32_t));
    {
        uint32_t max_pixel = 0;
        for (size_t i = 0; i < count; i++) if (rays[i].pixel > max_pixel) max_pixel = rays[i].pixel;
        uint32_t *seen = calloc((size_t)(max_pixel + 1) * 4, sizeof(uint32_t));
        if (!seen) { fprintf(stderr, "out of memory\n"); return 2; }
        for (size_t i = 0; i < count; i++) rank_of[i] = seen[(size_t)rays[i].pixel * 4 + (rays[i].cls & 3)]++;
        free(seen);
    }
    W = atoi(argv[3]);
    int reps = argc > 4 ? atoi(argv[4]) : 3;
    const char *only = argc > 5 ? argv[5] : NULL;
    if (W < 1) { fprintf(stderr, "bad WIDTH\n"); return 2; }
    if (reps < 1 || reps > 100) reps = 3;
    printf("triangles %zu\nrays %zu\n", m.nt, count);
    static const char *CLASS[4] = {"primary", "shadow", "reflection", "refraction"};
    Class cls[4];
    for (int k = 0; k < 4; k++) prepare(&cls[k], rays, count, (uint32_t)k);

    // EMBREE_CONFIG replaces the device configuration (one thread either way: say
    // threads=1 in it), e.g. "threads=1,hugepages=1" for Embree's own large pages.
    const char *config = getenv("EMBREE_CONFIG");
    RTCDevice dev = rtcNewDevice(config && *config ? config : "threads=1");
    if (!dev) { fprintf(stderr, "rtcNewDevice(\"%s\") failed\n", config ? config : ""); return 2; }
    const char *BUILD[3] = {"refit", "high", "robust"};
    // Which (build, class, API) run: all, or the one ONLY names (NULL scenes are not built).
    int run[3][4][APIS], any = 0;
    RTCScene scenes[3] = {NULL, NULL, NULL};
    for (int b = 0; b < 3; b++)
        for (int k = 0; k < 4; k++)
            for (int api = 0; api < APIS; api++) {
                char key[64];
                snprintf(key, sizeof key, "%s:%s:%s", BUILD[b], CLASS[k], API_NAME[api]);
                run[b][k][api] = cls[k].n > 0 && (!only || !strcmp(key, only));
                any |= run[b][k][api];
                if (run[b][k][api] && !scenes[b]) scenes[b] = make_scene(dev, &m, b);
            }
    if (!any) {
        if (only) fprintf(stderr, "nothing to trace: %s is no BUILD:CLASS:API with rays in this file\n", only);
        else fprintf(stderr, "nothing to trace: the file holds no rays\n");
        return 2;
    }
    // ONLY (instructions_side_by_side.sh) counts instructions: one pass a repetition.
    const double min_sample_ms = only ? 0.0 : MIN_SAMPLE_MS;
    static double ms[3][4][APIS][100];
    long hits[3][4][APIS], agree[3][4][APIS];
    for (int rep = 0; rep < reps; rep++)
        for (int b = 0; b < 3; b++)
            for (int k = 0; k < 4; k++) {
                for (int api = 0; api < APIS; api++) {
                    if (!run[b][k][api]) continue;
                    // One sample: passes back to back until MIN_SAMPLE_MS have gone by (one
                    // pass for any class that takes longer), the time divided by their number,
                    // as `mipray bench --rays` times its samples: a small class (Kitchen's
                    // 2,250 glass rays, under a millisecond) is timed warm on both sides.
                    double a = now_ms(), elapsed;
                    int passes = 0;
                    do {
                        hits[b][k][api] = trace_api(api, scenes[b], &cls[k], k == 1, &agree[b][k][api]);
                        passes++;
                        elapsed = now_ms() - a;
                    } while (elapsed < min_sample_ms);
                    ms[b][k][api][rep] = elapsed / passes;
                }
            }
    for (int b = 0; b < 3; b++)
        for (int k = 0; k < 4; k++) {
            for (int api = 0; api < APIS; api++) {
                if (!run[b][k][api]) continue;
                double *v = ms[b][k][api];
                qsort(v, reps, sizeof(double), cmp_d);
                printf("ray %s %s %s %zu %ld %.3f %.3f %ld\n", BUILD[b], CLASS[k], API_NAME[api], cls[k].n,
                       hits[b][k][api], cls[k].n / v[0] / 1e3, cls[k].n / v[reps / 2] / 1e3, agree[b][k][api]);
            }
        }
    for (int b = 0; b < 3; b++) if (scenes[b]) rtcReleaseScene(scenes[b]);
    rtcReleaseDevice(dev);
    return 0;
}
