/* The commands of heatvox, one per tools/cmd_<name>.c; tools/heatvox.c
 * dispatches to them. */
#ifndef HV_TOOLS_COMMANDS_H
#define HV_TOOLS_COMMANDS_H

int cmd_bench(int argc, char **argv);
int cmd_bench_sdf(int argc, char **argv);
int cmd_bench_mesh(int argc, char **argv);
int cmd_bench_sdf2d(int argc, char **argv);
int cmd_bench_band(int argc, char **argv);
int cmd_bench_points(int argc, char **argv);
int cmd_sdf(int argc, char **argv);
int cmd_info(int argc, char **argv);
int cmd_devices(int argc, char **argv);
int cmd_batch(int argc, char **argv);
int cmd_sdf2d(int argc, char **argv);
int cmd_slice(int argc, char **argv);
int cmd_make_scenes(int argc, char **argv);
int cmd_distance(int argc, char **argv);
int cmd_extend(int argc, char **argv);

/* heatvox bench extend (tools/bench/bench_extend.c). */
int bench_extend(int argc, char **argv);

#endif
