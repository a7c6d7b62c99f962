/* heatvox info: reads meshes and prints their defect reports. */
#include "cli.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void help(void)
{
    printf("usage: heatvox info [--json] [-q] MESH...\n"
           "\n"
           "Reads each mesh (OBJ, PLY, STL or OFF: format from the extension, else the\n"
           "content; glTF .gltf/.glb, FBX, 3MF, COLLADA .dae, DirectX .x: through assimp,\n"
           "by the extension, the scene graph flattened), welds vertices by exact position\n"
           "and prints its defect report: boundary, non-manifold and inconsistently\n"
           "oriented edges, duplicate and degenerate faces, non-finite vertices,\n"
           "edge-connected components; and the unit the file declares, if any. An\n"
           "point cloud (.xyz .pts .xyzn, or a PLY of points) gets its point count, bounds\n"
           "and whether it has normals.\n"
           "\n"
           "  --json   one JSON object per mesh, one per line, on stdout; a mesh that fails\n"
           "           gives {\"file\": ..., \"error\": ...}\n"
           "  --help   this text\n"
           "\n"
           "exit: 0 all meshes read, 1 some mesh failed (heatvox info: FILE: reason on\n"
           "stderr), 2 usage error\n");
}

static void json_string(const char *s)
{
    putchar('"');
    for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
        if (*p == '"' || *p == '\\')
            printf("\\%c", *p);
        else if (*p < 0x20)
            printf("\\u%04x", *p);
        else
            putchar(*p);
    }
    putchar('"');
}

static void json_double(double x)
{
    if (isfinite(x))
        printf("%.17g", x);
    else
        printf("null");
}

static void print_json(const char *file, const hv_mesh *m, const hv_mesh_report *r, int has_bounds,
                       const double lo[3], const double hi[3], double seconds)
{
    printf("{\"file\":");
    json_string(file);
    printf(",\"format\":");
    json_string(m->format ? m->format : "");
    printf(",\"vertices\":%zu,\"input_vertices\":%zu,\"unreferenced_vertices\":%zu"
           ",\"triangles\":%zu,\"polygons_fanned\":%zu,\"edges\":%zu,\"boundary_edges\":%zu"
           ",\"nonmanifold_edges\":%zu,\"inconsistent_edges\":%zu,\"duplicate_faces\":%zu"
           ",\"degenerate_faces\":%zu,\"nonfinite_vertices\":%zu,\"components\":%zu"
           ",\"vertex_components\":%zu",
           r->vertices, r->input_vertices, r->unreferenced_vertices, r->triangles,
           r->polygons_fanned, r->edges, r->boundary_edges, r->nonmanifold_edges,
           r->inconsistent_edges, r->duplicate_faces, r->degenerate_faces, r->nonfinite_vertices,
           r->components, r->vertex_components);
    printf(",\"skipped_primitives\":%zu,\"unit_meters\":", m->skipped_primitives);
    if (m->unit_meters > 0)
        json_double(m->unit_meters);
    else
        printf("null");
    printf(",\"closed\":%s,\"consistent\":%s,\"signed_volume\":",
           r->boundary_edges == 0 && r->nonmanifold_edges == 0 ? "true" : "false",
           r->inconsistent_edges == 0 ? "true" : "false");
    json_double(r->signed_volume);
    printf(",\"bounds\":");
    if (has_bounds)
        printf("[[%.17g,%.17g,%.17g],[%.17g,%.17g,%.17g]]", lo[0], lo[1], lo[2], hi[0], hi[1],
               hi[2]);
    else
        printf("null");
    printf(",\"read_seconds\":%.6f}\n", seconds);
}

static void print_text(const char *file, const hv_mesh *m, const hv_mesh_report *r, int has_bounds,
                       const double lo[3], const double hi[3], double seconds)
{
    printf("%s\n", file);
    printf("  format              %s (read in %.3f s)\n", m->format ? m->format : "?", seconds);
    printf("  vertices            %zu (%zu in the file, %zu unused by any face and dropped)\n",
           r->vertices, r->input_vertices, r->unreferenced_vertices);
    printf("  triangles           %zu (%zu polygons fanned)\n", r->triangles, r->polygons_fanned);
    if (m->skipped_primitives)
        printf("  points and lines    %zu left out\n", m->skipped_primitives);
    if (m->unit_meters > 0)
        printf("  length unit         %g m, from the file%s\n", m->unit_meters,
               m->unit_meters != 1 ? " (--units m scales the coordinates to metres)" : "");
    else
        printf("  length unit         none in the file (--units m keeps the coordinates)\n");
    if (has_bounds)
        printf("  bounds              [%g %g %g] .. [%g %g %g] (the file's axes and units)\n",
               lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
    else
        printf("  bounds              none (no finite vertex)\n");
    printf("  edges               %zu\n", r->edges);
    printf("  boundary edges      %zu\n", r->boundary_edges);
    printf("  non-manifold edges  %zu\n", r->nonmanifold_edges);
    printf("  inconsistent edges  %zu\n", r->inconsistent_edges);
    printf("  duplicate faces     %zu\n", r->duplicate_faces);
    printf("  degenerate faces    %zu\n", r->degenerate_faces);
    printf("  non-finite vertices %zu\n", r->nonfinite_vertices);
    printf("  components          %zu edge-connected, %zu vertex-connected\n", r->components,
           r->vertex_components);
    printf("  signed volume       %g\n", r->signed_volume);
    char verdict[256] = "";
    size_t n = 0;
#define ADD(cond, text)                                                                            \
    if (cond)                                                                                      \
        n += (size_t)snprintf(verdict + n, sizeof verdict - n, "%s%s", n ? ", " : "", text);
    ADD(r->boundary_edges, "has holes");
    ADD(r->nonmanifold_edges, "non-manifold");
    ADD(r->inconsistent_edges, "inconsistently oriented");
    ADD(r->duplicate_faces, "duplicate faces");
    ADD(r->degenerate_faces, "degenerate faces");
    ADD(r->nonfinite_vertices, "NaN/Inf coordinates");
#undef ADD
    if (!n) {
        if (r->signed_volume < 0)
            snprintf(verdict, sizeof verdict, "closed, consistent, but inside out");
        else
            snprintf(verdict, sizeof verdict, "closed and consistently oriented");
    }
    printf("  verdict             %s\n", verdict);
}

/* A file that failed: the reason on stderr, and with --json its line. */
static void report_failure(const char *file, hv_status st, int json)
{
    const char *msg = hv_last_error();
    size_t fl = strlen(file);
    /* library messages start with the file name already */
    if (!strncmp(msg, file, fl) && msg[fl] == ':')
        fprintf(stderr, "heatvox info: %s\n", msg);
    else
        fprintf(stderr, "heatvox info: %s: %s%s%s\n", file, hv_status_str(st), *msg ? ": " : "",
                msg);
    if (json) {
        printf("{\"file\":");
        json_string(file);
        printf(",\"error\":");
        json_string(*msg ? msg : hv_status_str(st));
        printf("}\n");
    }
}

/* A point cloud: its points, bounds and normals; 1 when it fails to read. */
static int info_points(const char *file, int json)
{
    hv_points *P = NULL;
    double t0 = hv_now();
    hv_status st = hv_points_read(file, &P);
    double seconds = hv_now() - t0;
    if (st) {
        report_failure(file, st, json);
        return 1;
    }
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < 3 * P->count; i++) {
        lo[i % 3] = fmin(lo[i % 3], P->xyz[i]);
        hi[i % 3] = fmax(hi[i % 3], P->xyz[i]);
    }
    if (json) {
        printf("{\"file\":");
        json_string(file);
        printf(",\"format\":");
        json_string(P->format);
        printf(",\"points\":%zu,\"oriented\":%s,\"bounds\":[[%.17g,%.17g,%.17g],"
               "[%.17g,%.17g,%.17g]],\"read_seconds\":%.6f}\n",
               P->count, P->normals ? "true" : "false", lo[0], lo[1], lo[2], hi[0], hi[1], hi[2],
               seconds);
    } else if (cli_verbose >= 0) {
        printf("%s\n", file);
        printf("  format              %s (read in %.3f s)\n", P->format, seconds);
        printf("  points              %zu, %s\n", P->count,
               P->normals ? "each with a normal" : "without normals");
        printf("  bounds              [%g %g %g] .. [%g %g %g]\n", lo[0], lo[1], lo[2], hi[0],
               hi[1], hi[2]);
        printf("  verdict             %s\n",
               P->normals ? "an oriented point cloud (heatvox sdf takes it)"
                          : "an unoriented point cloud (heatvox sdf recovers its normals)");
    }
    hv_points_destroy(&P);
    return 0;
}

int cmd_info(int argc, char **argv)
{
    int json = 0, nfiles = 0, failed = 0;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "MESH", .kind = CLI_WORDS, .files = CLI_FILES_MESH},
        {.names = "--json", .kind = CLI_FLAG, .dst = &json, .val = 1},
        {.names = NULL},
    };
    const char **files = malloc((size_t)argc * sizeof *files);
    if (!files)
        return cli_fail("info", "reading the command line", HV_ERR_NOMEM);
    int rc = cli_parse_words("info", argc, argv, opts, "mesh", files, argc, &nfiles, help);
    if (rc < 0 && !nfiles)
        rc = cli_usage_error("info", "no mesh given");
    if (rc >= 0) {
        free(files);
        return rc;
    }
    int first = 1;
    for (int i = 0; i < nfiles; i++) {
        const char *file = files[i];
        if (hv_points_file(file)) {
            if (!first && !json && cli_verbose >= 0)
                putchar('\n');
            failed |= info_points(file, json);
            first = 0;
            continue;
        }
        hv_mesh *m = NULL;
        hv_mesh_report r;
        double t0 = hv_now();
        hv_status st = hv_mesh_read(file, &m);
        double seconds = hv_now() - t0;
        if (!st)
            st = hv_mesh_report_compute(m, &r);
        if (st) {
            report_failure(file, st, json);
            hv_mesh_destroy(&m);
            failed = 1;
            continue;
        }
        double lo[3], hi[3];
        int has_bounds = hv_mesh_bounds(m, lo, hi) == HV_OK;
        if (json)
            print_json(file, m, &r, has_bounds, lo, hi, seconds);
        else if (cli_verbose >= 0) {
            if (!first)
                putchar('\n');
            print_text(file, m, &r, has_bounds, lo, hi, seconds);
        }
        first = 0;
        hv_mesh_destroy(&m);
    }
    fflush(stdout);
    free(files);
    return failed ? HV_EXIT_FAIL : HV_EXIT_OK;
}
