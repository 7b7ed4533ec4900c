// Embree 3's memory for a refittable BVH over a grid of N triangles: the yardstick for
// mipray's peak memory per million triangles (BENCHMARKS.md, "Update cost and memory").
//
// usage: cc -O2 -o embree_memory embree_memory.c -lembree3 -lm && ./embree_memory [TRIANGLES]
//        (default 1000000; needs apt-get install -y libembree-dev; all hardware threads)
//
// The mesh is a square grid of quads (two triangles each) in shared vertex and index
// buffers (12 bytes per vertex, 12 per triangle), as mipray's generated skinned grid is. The
// scene is built as a dynamic scene with refit quality (what an animated mesh uses), then
// every vertex is moved and the scene committed again (a refit). Printed, in MB and in
// bytes per triangle: Embree's own allocations at their peak (its memory monitor callback),
// the process's peak resident growth over the build and the refit (VmHWM above the resident
// size before the buffers were allocated), and the shared buffers themselves.
#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static long long embree_now = 0, embree_peak = 0;

static bool monitor(void *user, ssize_t bytes, bool post) {
    (void)user;
    (void)post;
    embree_now += bytes;
    if (embree_now > embree_peak) embree_peak = embree_now;
    return true;
}

// A /proc/self/status field in kB (-1 when absent).
static long status_kb(const char *field) {
    FILE *f = fopen("/proc/self/status", "r");
    if (!f) return -1;
    char line[256];
    long kb = -1;
    size_t n = strlen(field);
    while (fgets(line, sizeof line, f))
        if (strncmp(line, field, n) == 0) kb = atol(line + n);
    fclose(f);
    return kb;
}

int main(int argc, char **argv) {
    long want = argc > 1 ? atol(argv[1]) : 1000000;
    if (want < 2) want = 2;
    int side = (int)ceil(sqrt(want / 2.0));
    long verts = (long)(side + 1) * (side + 1), tris = 2L * side * side;

    FILE *reset = fopen("/proc/self/clear_refs", "w");
    if (reset) { fputs("5", reset); fclose(reset); }
    long start_kb = status_kb("VmRSS:");

    RTCDevice dev = rtcNewDevice(NULL);
    rtcSetDeviceMemoryMonitorFunction(dev, monitor, NULL);
    RTCScene s = rtcNewScene(dev);
    rtcSetSceneFlags(s, RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneBuildQuality(s, RTC_BUILD_QUALITY_LOW);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_REFIT);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                       3 * sizeof(float), verts);
    unsigned *ix = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                           3 * sizeof(unsigned), tris);
    for (int y = 0; y <= side; y++)
        for (int x = 0; x <= side; x++) {
            float *p = v + 3 * ((long)y * (side + 1) + x);
            p[0] = (float)x / side; p[1] = (float)y / side; p[2] = 0.0f;
        }
    long t = 0;
    for (int y = 0; y < side; y++)
        for (int x = 0; x < side; x++) {
            unsigned a = y * (side + 1) + x, b = a + 1, c = a + side + 1, d = c + 1;
            unsigned q[6] = {a, b, d, a, d, c};
            memcpy(ix + 3 * t, q, sizeof q);
            t += 2;
        }
    rtcCommitGeometry(g);
    rtcAttachGeometry(s, g);
    rtcCommitScene(s);
    long built_kb = status_kb("VmHWM:");

    // A refit: every vertex moves.
    for (long i = 0; i < verts; i++) v[3 * i + 2] = 0.1f * sinf(7.0f * v[3 * i]);
    rtcUpdateGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0);
    rtcCommitGeometry(g);
    rtcCommitScene(s);
    long refit_kb = status_kb("VmHWM:");

    double mb = 1.0 / (1024.0 * 1024.0), per = 1.0 / (double)tris;
    double buffers = (double)verts * 12 + (double)tris * 12;
    printf("triangles %ld, vertices %ld\n", tris, verts);
    printf("shared vertex+index buffers: %.1f MB (%.1f B/triangle)\n", buffers * mb, buffers * per);
    printf("Embree allocations at peak (memory monitor): %.1f MB (%.1f B/triangle)\n",
           embree_peak * mb, embree_peak * per);
    printf("Embree allocations after the refit: %.1f MB (%.1f B/triangle)\n",
           embree_now * mb, embree_now * per);
    printf("peak resident growth, build: %.1f MB (%.1f B/triangle)\n",
           (built_kb - start_kb) / 1024.0, (built_kb - start_kb) * 1024.0 * per);
    printf("peak resident growth, build + refit: %.1f MB (%.1f B/triangle)\n",
           (refit_kb - start_kb) / 1024.0, (refit_kb - start_kb) * 1024.0 * per);
    rtcReleaseGeometry(g);
    rtcReleaseScene(s);
    rtcReleaseDevice(dev);
    return 0;
}
