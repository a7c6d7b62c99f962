/* The shape an sdf takes from a file: a mesh, or the closed surface of a
 * point cloud. */
#include "cli.h"

#include <stdio.h>
#include <string.h>

hv_status cli_read_shape(const char *path, const hv_sdf_opts *o, hv_mesh **m, hv_points_report *pr)
{
    memset(pr, 0, sizeof *pr);
    *m = NULL;
    if (!hv_points_file(path))
        return hv_mesh_read(path, m);
    hv_points *P = NULL;
    hv_status st = hv_points_read(path, &P);
    if (!st)
        st = hv_points_surface(P, o, m, pr);
    hv_points_destroy(&P);
    return st;
}

int cli_own_surface(const hv_points_report *pr, const hv_sdf_opts *o, double adaptivity)
{
    return pr->points && adaptivity == 0 &&
           !(o->close > 0 || o->open > 0 || o->offset != 0 || o->shell > 0);
}

void cli_points_note(const char *cmd, const char *path, const hv_points_report *pr)
{
    if (!pr->points)
        return;
    if (pr->recovered)
        cli_info("heatvox %s: %s: orientation recovered from the points: spread off their planes "
                 "%.3f (median), directions from %s; %zu components of the neighbour graph (%zu "
                 "turned outward), %zu points of thin parts voted by rays and %zu turned, %d "
                 "heat rounds turned %zu points, %.2f s; %zu points against the file's "
                 "normals\n",
                 cmd, path, pr->orient_spread,
                 pr->orient_lines ? "the diffused line field" : "the neighbourhoods' axes",
                 pr->orient_components, pr->orient_components_flipped, pr->orient_thin_votes,
                 pr->orient_thin_turned, pr->orient_rounds, pr->orient_turned, pr->t_orient,
                 pr->orient_disagree);
    cli_info("heatvox %s: %s: %zu points, spacing %.4g (%.4g to %.4g); %zu normals "
             "(%.1f%% of the area) pointed into the surface and were turned; heat grid "
             "%dx%dx%d h=%.6g; surface of %zu vertices, %zu with no point within reach, moved "
             "%.3f voxels on average (at most %.3f), noise %.3g, kernel %.3g; s: spacing %.2f "
             "heat %.2f mesh %.2f project %.2f\n",
             cmd, path, pr->points, pr->spacing_median, pr->spacing_min, pr->spacing_max,
             pr->normals_against, 100 * (1 - pr->normal_agreement), pr->n[0], pr->n[1], pr->n[2],
             pr->h, pr->vertices, pr->vertices_unsupported, pr->move_mean, pr->move_max, pr->noise,
             pr->sigma, pr->t_spacing, pr->t_heat, pr->t_mesh, pr->t_project);
}
