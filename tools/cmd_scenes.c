/* heatvox make-scenes: writes the generated demo inputs (broken meshes, a level
 * set with a velocity field, sources and obstacles for geodesic distance) into
 * a directory. Deterministic: the same files every run. The hand-written
 * inputs (curves, the batch manifest) and the READMEs live in the repository's
 * scenes/ directory. */
#include "cli.h"

#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

static void help(void)
{
    printf("usage: heatvox make-scenes [DIR]   (default DIR: scenes)\n"
           "\n"
           "Writes generated test inputs, the same every run:\n"
           "  DIR/meshes/sphere_holes_flips.obj   icosphere, 3 holes, 25%% faces flipped\n"
           "  DIR/meshes/torus_holes.obj          torus, 4 holes\n"
           "  DIR/meshes/sphere_half_flipped.obj  icosphere, the +x half inside out, 5%%\n"
           "                                      duplicated faces\n"
           "  DIR/meshes/torus_soup.obj           torus as a soup (every triangle its own\n"
           "                                      vertices), 10%% flipped\n"
           "  DIR/meshes/truncated.obj            a file cut off mid-face (malformed)\n"
           "  DIR/points/torus_scan.xyz           a torus scanned as oriented points: uneven\n"
           "                                      density, noise, 10%% of the normals turned\n"
           "                                      around, a patch missing\n"
           "  DIR/points/torus_scan_bare.xyz      the same points without their normals\n"
           "  DIR/levelset/sphere_velocity.vdb    sphere level set (radius 1, 64^3) and a\n"
           "                                      rotation about z (grids \"sdf\", \"v\")\n"
           "  DIR/distance/sources.txt            one source point (heatvox distance)\n"
           "  DIR/distance/sources_2d.txt         the same point for --dim 2\n"
           "  DIR/distance/sources_east.txt       a second source set: a point in the east room\n"
           "  DIR/distance/walls.vdb              bool grid \"walls\", 64 x 48 x 16: two walls,\n"
           "                                      each with a gap at the opposite end\n"
           "  DIR/distance/building.obj           a one-room-deep building of boxes: floor,\n"
           "                                      roof, outer walls with a door, a partition\n"
           "                                      with a doorway, a sealed closet\n"
           "\n"
           "exit: 0 written, 1 failure, 2 usage error\n");
}

static int make_dir(const char *path)
{
    if (mkdir(path, 0777) != 0 && errno != EEXIST) {
        fprintf(stderr, "heatvox make-scenes: %s: cannot create: %s\n", path, strerror(errno));
        return -1;
    }
    return 0;
}

/* Writes a text file under a temporary name, renamed when complete. */
static int write_text(const char *path, const char *text)
{
    char tmp[4096];
    hv_status st = hv_tmp_name(path, tmp, sizeof tmp);
    if (st)
        return cli_fail("make-scenes", path, st);
    FILE *f = fopen(tmp, "w");
    int ok = f && fputs(text, f) >= 0;
    int e = errno;
    /* A full disk shows only when the buffer is flushed. */
    if (f && fclose(f) != 0 && ok) {
        ok = 0;
        e = errno;
    }
    if (!ok) {
        hv_tmp_discard(tmp);
        fprintf(stderr, "heatvox make-scenes: %s: cannot write: %s\n", path, strerror(e));
        return 1;
    }
    if ((st = hv_tmp_commit(tmp, path)))
        return cli_fail("make-scenes", path, st);
    return 0;
}

static int write_mesh(const char *dir, const char *name, hv_mesh *m)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/meshes/%s", dir, name);
    hv_status st = hv_mesh_write_obj(m, path);
    if (st)
        return cli_fail("make-scenes", path, st);
    hv_mesh_report r;
    if (cli_verbose >= 0 && hv_mesh_report_compute(m, &r) == HV_OK)
        printf("%-40s %6zu triangles, %4zu boundary edges, %5zu inconsistent edges, %4zu "
               "duplicates\n",
               path, r.triangles, r.boundary_edges, r.inconsistent_edges, r.duplicate_faces);
    return 0;
}

static int meshes(const char *dir)
{
    const double c0[3] = {0, 0, 0}, c1[3] = {0.1, -0.05, 0.2};
    hv_mesh *m = NULL;
    hv_status st;
    int rc = 0;
    /* sphere with holes and random flips */
    if ((st = hv_mesh_make_sphere(&m, c0, 1.0, 4)) || (st = hv_mesh_defect_holes(m, 3, 0.04, 7)) ||
        (st = hv_mesh_defect_flip(m, 0.25, 11)))
        return cli_fail("make-scenes", "sphere_holes_flips", st);
    rc |= write_mesh(dir, "sphere_holes_flips.obj", m);
    hv_mesh_destroy(&m);
    /* torus with holes */
    if ((st = hv_mesh_make_torus(&m, c1, 1.0, 0.35, 64, 32)) ||
        (st = hv_mesh_defect_holes(m, 4, 0.03, 13)))
        return cli_fail("make-scenes", "torus_holes", st);
    rc |= write_mesh(dir, "torus_holes.obj", m);
    hv_mesh_destroy(&m);
    /* sphere half inside out, with duplicated faces */
    if ((st = hv_mesh_make_sphere(&m, c1, 0.8, 3)) || (st = hv_mesh_defect_flip_half(m, 0)) ||
        (st = hv_mesh_defect_duplicate(m, 0.05, 17)))
        return cli_fail("make-scenes", "sphere_half_flipped", st);
    rc |= write_mesh(dir, "sphere_half_flipped.obj", m);
    hv_mesh_destroy(&m);
    /* torus soup */
    if ((st = hv_mesh_make_torus(&m, c0, 0.9, 0.3, 48, 24)) ||
        (st = hv_mesh_defect_soup(m, 0, 19)) || (st = hv_mesh_defect_flip(m, 0.1, 23)))
        return cli_fail("make-scenes", "torus_soup", st);
    rc |= write_mesh(dir, "torus_soup.obj", m);
    hv_mesh_destroy(&m);
    /* a malformed file: the last face is cut off */
    char path[1024];
    snprintf(path, sizeof path, "%s/meshes/truncated.obj", dir);
    if (write_text(path, "# cut off while writing\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                         "f 1 2 3\nf 1 3 4\nf 1 4"))
        return 1;
    if (cli_verbose >= 0)
        printf("%-40s malformed on purpose\n", path);
    return rc;
}

/* Deterministic uniform numbers in [0, 1). */
static double lcg(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0;
}

/* One point of the scan: uniform by area on the torus (rejection on the
 * area element), then its defects. 0 when dropped. */
static int scan_point(uint64_t *s, double R, double r, double out[6])
{
    const double u = 2 * M_PI * lcg(s), v = 2 * M_PI * lcg(s);
    if (lcg(s) * (R + r) > R + r * cos(v))
        return 0;
    const double n[3] = {cos(v) * cos(u), cos(v) * sin(u), sin(v)};
    const double p[3] = {R * cos(u) + r * n[0], R * sin(u) + r * n[1], r * n[2]};
    /* density 5:1 from -x to +x; a patch of radius 0.3 missing at (R + r, 0, 0) */
    const double gap = (p[0] - R - r) * (p[0] - R - r) + p[1] * p[1] + p[2] * p[2];
    if (lcg(s) > 0.2 + 0.8 * (p[0] + R + r) / (2 * (R + r)) || gap < 0.09)
        return 0;
    const double noise = 0.004 * (lcg(s) + lcg(s) + lcg(s) - 1.5) * 2;
    const double sign = lcg(s) < 0.1 ? -1 : 1;
    for (int a = 0; a < 3; a++) {
        out[a] = p[a] + noise * n[a];
        out[3 + a] = sign * n[a];
    }
    return 1;
}

static int points(const char *dir)
{
    enum { COUNT = 12000 };
    char path[1024], *text = malloc((size_t)COUNT * 96 + 128),
                     *bare = malloc((size_t)COUNT * 48 + 128);
    if (!text || !bare) {
        free(text), free(bare);
        return cli_fail("make-scenes", "torus_scan", HV_ERR_NOMEM);
    }
    size_t len = (size_t)snprintf(text, 128,
                                  "# heatvox make-scenes: a torus (R 1, r 0.35) as "
                                  "oriented points\n# x y z nx ny nz\n");
    size_t blen = (size_t)snprintf(bare, 128,
                                   "# heatvox make-scenes: the torus scan's points without "
                                   "their normals\n# x y z\n");
    uint64_t s = 29;
    for (int k = 0; k < COUNT;) {
        double q[6];
        if (!scan_point(&s, 1.0, 0.35, q))
            continue;
        len += (size_t)snprintf(text + len, 96, "%.6f %.6f %.6f %.5f %.5f %.5f\n", q[0], q[1], q[2],
                                q[3], q[4], q[5]);
        blen += (size_t)snprintf(bare + blen, 48, "%.6f %.6f %.6f\n", q[0], q[1], q[2]);
        k++;
    }
    snprintf(path, sizeof path, "%s/points/torus_scan.xyz", dir);
    int rc = write_text(path, text);
    if (!rc && cli_verbose >= 0)
        printf("%-40s %d oriented points\n", path, COUNT);
    snprintf(path, sizeof path, "%s/points/torus_scan_bare.xyz", dir);
    if (!rc && !(rc = write_text(path, bare)) && cli_verbose >= 0)
        printf("%-40s %d points without normals\n", path, COUNT);
    free(text), free(bare);
    return rc;
}

static int levelset(const char *dir)
{
    int n[3] = {64, 64, 64};
    double h = 3.0 / 64, org[3] = {-1.5, -1.5, -1.5};
    hv_grid *phi = NULL, *v[3] = {NULL, NULL, NULL};
    hv_status st = hv_grid_create(&phi, 3, n, h, org);
    for (int a = 0; a < 3 && !st; a++)
        st = hv_grid_create(&v[a], 3, n, h, org);
    if (st)
        return cli_fail("make-scenes", "level set", st);
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                double x[3];
                hv_grid_cell_center(phi, i, j, k, x);
                size_t c = (size_t)i + (size_t)n[0] * (j + (size_t)n[1] * k);
                phi->v[c] = (float)(sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - 1.0);
                /* rigid rotation about z, one radian per unit time */
                v[0]->v[c] = (float)-x[1];
                v[1]->v[c] = (float)x[0];
                v[2]->v[c] = 0.0f;
            }
    char path[1024];
    snprintf(path, sizeof path, "%s/levelset/sphere_velocity.vdb", dir);
    hv_vdb_writer *w = NULL;
    st = hv_vdb_writer_create(&w);
    if (!st)
        st = hv_vdb_writer_add_levelset(w, phi, "sdf", 3.0, 0);
    if (!st)
        st = hv_vdb_writer_add_vec3(w, v[0], v[1], v[2], "v");
    if (!st)
        st = hv_vdb_writer_set_meta(w, "source", "heatvox make-scenes: sphere r=1, v = (-y, x, 0)");
    if (!st)
        st = hv_vdb_writer_write(w, path);
    hv_vdb_writer_destroy(&w);
    hv_grid_destroy(&phi);
    for (int a = 0; a < 3; a++)
        hv_grid_destroy(&v[a]);
    if (st)
        return cli_fail("make-scenes", path, st);
    if (cli_verbose >= 0)
        printf("%-40s sphere level set \"sdf\" 64^3 and velocity \"v\"\n", path);
    return 0;
}

/* Appends the axis-aligned box [lo, hi] as 12 triangles, outward facing. */
static void add_box(double *verts, uint32_t *tris, size_t *nv, size_t *nt, const double lo[3],
                    const double hi[3])
{
    /* corner c = (c & 1 ? hi : lo) in x, (c & 2) in y, (c & 4) in z */
    static const int quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                    {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
    uint32_t v0 = (uint32_t)*nv;
    for (int c = 0; c < 8; c++) {
        verts[3 * *nv + 0] = c & 1 ? hi[0] : lo[0];
        verts[3 * *nv + 1] = c & 2 ? hi[1] : lo[1];
        verts[3 * *nv + 2] = c & 4 ? hi[2] : lo[2];
        (*nv)++;
    }
    for (int q = 0; q < 6; q++) {
        const int *c = quads[q];
        uint32_t t[6] = {c[0], c[1], c[2], c[0], c[2], c[3]};
        for (int k = 0; k < 6; k++)
            tris[3 * *nt + k] = v0 + t[k];
        *nt += 2;
    }
}

/* Inputs for heatvox distance. Both obstacle sets fill the box [0,4] x [0,3] x
 * [0,1], and the source point (0.5, 1.5, 0.5) lies in free space in each. */
static int distance_inputs(const char *dir)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/distance/sources.txt", dir);
    if (write_text(path, "# heatvox distance sources: one per line, \"x y z\" (a world point),\n"
                         "# \"voxel i j k\" or \"mesh PATH\"; '#' starts a comment.\n"
                         "0.5 1.5 0.5\n"))
        return 1;
    if (cli_verbose >= 0)
        printf("%-40s one source point (0.5, 1.5, 0.5)\n", path);
    snprintf(path, sizeof path, "%s/distance/sources_2d.txt", dir);
    if (write_text(path, "# heatvox distance --dim 2 sources: \"x y\" per line.\n0.5 1.5\n"))
        return 1;
    if (cli_verbose >= 0)
        printf("%-40s the same point for --dim 2\n", path);
    snprintf(path, sizeof path, "%s/distance/sources_east.txt", dir);
    if (write_text(path, "# a second source set for heatvox distance: a point in the east room.\n"
                         "3.5 1.5 0.5\n"))
        return 1;
    if (cli_verbose >= 0)
        printf("%-40s a point in the east room (3.5, 1.5, 0.5)\n", path);

    /* walls.vdb: voxels of 1/16 over [0,4] x [0,3] x [0,1]; a wall across
     * x = 1.25..1.375 open for y > 2.25, another across x = 2.625..2.75 open
     * for y < 0.75, so the way from the left room to the right snakes. */
    int n[3] = {64, 48, 16};
    double org[3] = {0, 0, 0};
    hv_grid *g = NULL;
    hv_status st = hv_grid_create(&g, 3, n, 1.0 / 16, org);
    if (!st)
        st = hv_grid_add_mask(g);
    if (st) {
        hv_grid_destroy(&g);
        return cli_fail("make-scenes", "walls", st);
    }
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                int solid = ((i == 20 || i == 21) && j < 36) || ((i == 42 || i == 43) && j >= 12);
                g->solid[(size_t)i + (size_t)n[0] * (j + (size_t)n[1] * k)] = (uint8_t)solid;
            }
    snprintf(path, sizeof path, "%s/distance/walls.vdb", dir);
    hv_vdb_writer *w = NULL;
    st = hv_vdb_writer_create(&w);
    if (!st)
        st = hv_vdb_writer_add_mask(w, g, "walls");
    if (!st)
        st = hv_vdb_writer_set_meta(w, "source",
                                    "heatvox make-scenes: two walls with gaps at "
                                    "opposite ends, voxel 1/16 over [0,4]x[0,3]x[0,1]");
    if (!st)
        st = hv_vdb_writer_write(w, path);
    hv_vdb_writer_destroy(&w);
    hv_grid_destroy(&g);
    if (st)
        return cli_fail("make-scenes", path, st);
    if (cli_verbose >= 0)
        printf("%-40s bool grid \"walls\" 64 x 48 x 16, two walls with gaps\n", path);

    /* building.obj: walls 0.1 thick around the room [0,4] x [0,3] x [0,1], a
     * door in the south wall (x = 2.6..3.4, up to z = 0.8), a partition at
     * x = 2 with a doorway at y = 2.2..2.8, and a closed box (a sealed closet:
     * its inside is unreachable). */
    static const double boxes[][6] = {
        {-0.1, -0.1, -0.1, 4.1, 3.1, 0.0}, /* floor */
        {-0.1, -0.1, 1.0, 4.1, 3.1, 1.1},  /* roof */
        {-0.1, -0.1, 0.0, 0.0, 3.1, 1.0},  /* west wall */
        {4.0, -0.1, 0.0, 4.1, 3.1, 1.0},   /* east wall */
        {0.0, 3.0, 0.0, 4.0, 3.1, 1.0},    /* north wall */
        {0.0, -0.1, 0.0, 2.6, 0.0, 1.0},   /* south wall, left of the door */
        {3.4, -0.1, 0.0, 4.0, 0.0, 1.0},   /* south wall, right of the door */
        {2.6, -0.1, 0.8, 3.4, 0.0, 1.0},   /* above the door */
        {1.95, 0.0, 0.0, 2.05, 2.2, 1.0},  /* partition, below the doorway */
        {1.95, 2.8, 0.0, 2.05, 3.0, 1.0},  /* partition, above the doorway */
        {3.2, 2.2, 0.0, 3.8, 2.8, 1.0},    /* sealed closet */
    };
    enum { NBOX = sizeof boxes / sizeof boxes[0] };
    double verts[NBOX * 8 * 3];
    uint32_t tris[NBOX * 12 * 3];
    size_t nv = 0, nt = 0;
    for (int b = 0; b < NBOX; b++)
        add_box(verts, tris, &nv, &nt, boxes[b], boxes[b] + 3);
    hv_mesh *m = NULL;
    snprintf(path, sizeof path, "%s/distance/building.obj", dir);
    if ((st = hv_mesh_from_arrays(&m, verts, nv, tris, nt)) || (st = hv_mesh_write_obj(m, path))) {
        hv_mesh_destroy(&m);
        return cli_fail("make-scenes", path, st);
    }
    hv_mesh_destroy(&m);
    if (cli_verbose >= 0)
        printf("%-40s %d boxes: walls, a door, a doorway, a closet\n", path, (int)NBOX);
    return 0;
}

int cmd_make_scenes(int argc, char **argv)
{
    const char *dir = NULL;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "DIRECTORY", .kind = CLI_WORDS, .files = CLI_FILES_DIR},
        {.names = NULL},
    };
    int rc = cli_parse("make-scenes", argc, argv, opts, "directory", &dir, help);
    if (rc >= 0)
        return rc;
    if (!dir)
        dir = "scenes";
    char sub[1024];
    if (make_dir(dir))
        return HV_EXIT_FAIL;
    snprintf(sub, sizeof sub, "%s/meshes", dir);
    if (make_dir(sub) || meshes(dir))
        return HV_EXIT_FAIL;
    snprintf(sub, sizeof sub, "%s/points", dir);
    if (make_dir(sub) || points(dir))
        return HV_EXIT_FAIL;
    snprintf(sub, sizeof sub, "%s/levelset", dir);
    if (make_dir(sub) || levelset(dir))
        return HV_EXIT_FAIL;
    snprintf(sub, sizeof sub, "%s/distance", dir);
    if (make_dir(sub) || distance_inputs(dir))
        return HV_EXIT_FAIL;
    return HV_EXIT_OK;
}
