/* Shared pieces of the heatvox command: each command lives in tools/cmd_<name>.c
 * and uses only the public headers. */
#ifndef HV_TOOLS_CLI_H
#define HV_TOOLS_CLI_H

#include "heatvox/heatvox.h"

/* Exit codes (documented in README.md). */
enum { HV_EXIT_OK = 0, HV_EXIT_FAIL = 1, HV_EXIT_USAGE = 2 };

extern int cli_verbose; /* -1 quiet (-q), 0 default, 1 verbose (-v) */

/* Prints "heatvox <cmd>: <what>: <status>: <hv_last_error()>" on stderr and
 * returns HV_EXIT_FAIL. */
int cli_fail(const char *cmd, const char *what, hv_status st);
/* Prints "heatvox <cmd>: <message>" and a hint to --help; returns HV_EXIT_USAGE. */
int cli_usage_error(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Parses numbers strictly (whole string, finite); 0 on success. */
int cli_parse_int(const char *s, int *out);
int cli_parse_double(const char *s, double *out);
/* True when argv[i] is `name`, and a value follows (else reports a usage error via *err). */
int cli_info(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

int cmd_bench(int argc, char **argv);
int cmd_bench_sdf(int argc, char **argv);
int cmd_sdf(int argc, char **argv);
int cmd_info(int argc, char **argv);
int cmd_devices(int argc, char **argv);
int cmd_batch(int argc, char **argv);
int cmd_sdf2d(int argc, char **argv);
int cmd_slice(int argc, char **argv);
int cmd_make_scenes(int argc, char **argv);
int cmd_distance(int argc, char **argv);
int cmd_extend(int argc, char **argv);

/* heatvox bench extend (tools/bench_extend.c). */
int bench_extend(int argc, char **argv);

#endif
