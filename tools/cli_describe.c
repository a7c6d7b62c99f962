/* `heatvox CMD --describe-options`: a command's option rows as lines a
 * program reads (declared in cli.h). tools/man_completion.py turns them,
 * with each command's --help, into the man pages and the bash completion,
 * so that both list exactly what the parser takes. */
#include "cli.h"

#include <stdio.h>
#include <string.h>

static const char *kind_name(cli_kind k)
{
    static const char *names[] = {
        [CLI_FLAG] = "flag",      [CLI_OR] = "flag",       [CLI_STR] = "string",
        [CLI_INT] = "int",        [CLI_DOUBLE] = "number", [CLI_DOUBLES] = "numbers",
        [CLI_BACKEND] = "choice", [CLI_THREADS] = "int",   [CLI_SIGN] = "choice",
        [CLI_CHOICE] = "choice",  [CLI_LIST] = "list",     [CLI_IGNORE] = "flag",
        [CLI_FN] = "custom",      [CLI_WORDS] = "words",
    };
    return (size_t)k < sizeof names / sizeof names[0] ? names[k] : "custom";
}

/* The backends of a CLI_BACKEND mask, "auto|mg|...", one buffer per mask. */
static const char *backend_names(unsigned mask)
{
    static const hv_backend order[] = {HV_BACKEND_AUTO, HV_BACKEND_MG, HV_BACKEND_FFTW,
                                       HV_BACKEND_OPENCL, HV_BACKEND_PETSC};
    static char names[32][64];
    char *s = names[mask & 31];
    size_t n = 0;
    for (size_t i = 0; i < sizeof order / sizeof order[0]; i++)
        if (mask & CLI_BACKEND(order[i]))
            n += (size_t)snprintf(s + n, sizeof names[0] - n, "%s%s", n ? "|" : "",
                                  hv_backend_name(order[i]));
    return s;
}

const char *cli_opt_choices(const cli_opt *o)
{
    if (o->kind == CLI_BACKEND)
        return backend_names((unsigned)o->val);
    if (o->kind == CLI_SIGN)
        return "auto|heat|winding";
    return o->choices;
}

static const char *field(const char *s) { return s && *s ? s : "-"; }

int cli_describe(const char *cmd, const cli_opt *opts, const char *noun, int max)
{
    const char *files = NULL;
    for (const cli_opt *o = opts; o->names; o++)
        if (o->kind == CLI_WORDS) {
            noun = o->names;
            files = o->files;
        }
    printf("command\t%s\n", cmd);
    if (max > 0)
        printf("words\t%s\t%s\t%s\n", field(noun), max > 1 ? "many" : "1", field(files));
    for (const cli_opt *o = opts; o->names; o++) {
        if (o->kind == CLI_WORDS)
            continue;
        printf("option\t%s\t%s\t%d\t%s\t%s\t%s\n", o->names, kind_name(o->kind), cli_opt_arity(o),
               field(cli_opt_choices(o)), field(o->files), field(o->needs));
    }
    return HV_EXIT_OK;
}
