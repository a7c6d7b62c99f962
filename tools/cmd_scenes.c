/* heatvox make-scenes: writes the generated demo inputs (broken meshes, a level
 * set with a velocity field) into a directory. Deterministic: the same files
 * every run. The hand-written inputs (curves, the batch manifest) and the
 * READMEs live in the repository's scenes/ directory. */
#include "cli.h"

#include <errno.h>
#include <math.h>
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
           "  DIR/levelset/sphere_velocity.vdb    sphere level set (radius 1, 64^3) and a\n"
           "                                      rotation about z (grids \"sdf\", \"v\")\n"
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
    char path[1024], tmp[4096];
    snprintf(path, sizeof path, "%s/meshes/truncated.obj", dir);
    if ((st = hv_tmp_name(path, tmp, sizeof tmp)))
        return cli_fail("make-scenes", path, st);
    FILE *f = fopen(tmp, "w");
    int ok = f && fputs("# cut off while writing\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                        "f 1 2 3\nf 1 3 4\nf 1 4",
                        f) >= 0;
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
    if (cli_verbose >= 0)
        printf("%-40s malformed on purpose\n", path);
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

int cmd_make_scenes(int argc, char **argv)
{
    const char *dir = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            help();
            return HV_EXIT_OK;
        } else if (!strcmp(argv[i], "-q") || !strcmp(argv[i], "-v")) {
            continue;
        } else if (argv[i][0] == '-' && argv[i][1]) {
            return cli_usage_error("make-scenes", "unknown option '%s'", argv[i]);
        } else if (!dir) {
            dir = argv[i];
        } else {
            return cli_usage_error("make-scenes", "more than one directory given");
        }
    }
    if (!dir)
        dir = "scenes";
    char sub[1024];
    if (make_dir(dir))
        return HV_EXIT_FAIL;
    snprintf(sub, sizeof sub, "%s/meshes", dir);
    if (make_dir(sub) || meshes(dir))
        return HV_EXIT_FAIL;
    snprintf(sub, sizeof sub, "%s/levelset", dir);
    if (make_dir(sub) || levelset(dir))
        return HV_EXIT_FAIL;
    return HV_EXIT_OK;
}
