/* The man pages and the bash completion (make man, make completion: built
 * from `heatvox CMD --describe-options` by tools/man_completion.py) list
 * what the parsers take: every name of every option row of every command is
 * in its rendered man page and among the completion's words for it; the
 * completion offers the commands, the benchmarks, every option's choices and
 * files by their extensions; the pages render with man and with groff
 * without a warning. */
#include "testlib.h"

#include <check.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

static char bin[PATH_MAX], build[PATH_MAX - 64], dir[64];

static void setup(void)
{
    const char *b = tl_heatvox_bin();
    ck_assert_msg(b != NULL, "build/heatvox not found (set HEATVOX_BIN)");
    snprintf(bin, sizeof bin, "%s", b);
    ck_assert_int_lt(snprintf(build, sizeof build, "%s", b), (int)sizeof build);
    *strrchr(build, '/') = '\0';
    snprintf(dir, sizeof dir, "/tmp/hv_check_man_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
}

static void teardown(void)
{
    tl_rm_rf(dir);
    *dir = '\0';
}

/* The stdout of a shell command, NUL-terminated (the caller frees it); *rc
 * its exit code. */
static char *output(const char *cmd, int *rc)
{
    FILE *p = popen(cmd, "r");
    ck_assert_msg(p != NULL, "%s: cannot run", cmd);
    size_t n = 0, cap = 1 << 16;
    char *buf = malloc(cap);
    ck_assert_ptr_nonnull(buf);
    size_t got;
    while ((got = fread(buf + n, 1, cap - n - 1, p)) > 0)
        if ((n += got) + 1 == cap)
            ck_assert_ptr_nonnull(buf = realloc(buf, cap *= 2));
    buf[n] = '\0';
    const int st = pclose(p);
    *rc = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
    return buf;
}

static int have(const char *program)
{
    char cmd[128];
    snprintf(cmd, sizeof cmd, "command -v %s >/dev/null 2>&1", program);
    return system(cmd) == 0;
}

/* Whether word stands alone in text: no letter, digit or '-' either side. */
static int has_word(const char *text, const char *word)
{
    const size_t n = strlen(word);
    for (const char *p = strstr(text, word); p; p = strstr(p + 1, word)) {
        const char before = p == text ? ' ' : p[-1], after = p[n];
        if (!strchr("-_", before) && !strchr("-_", after) && !(before >= 'a' && before <= 'z') &&
            !(after >= 'a' && after <= 'z') && !(before >= 'A' && before <= 'Z') &&
            !(after >= 'A' && after <= 'Z') && !(before >= '0' && before <= '9') &&
            !(after >= '0' && after <= '9'))
            return 1;
    }
    return 0;
}

/* Whether line stands as a whole line of text. */
static int has_line(const char *text, const char *line)
{
    const size_t n = strlen(line);
    for (const char *p = strstr(text, line); p; p = strstr(p + 1, line))
        if ((p == text || p[-1] == '\n') && (p[n] == '\n' || !p[n]))
            return 1;
    return 0;
}

/* The commands, "sdf", ..., and the benchmarks, "bench solve", ...: those
 * that have option rows (leaves), or all (the pages). */
#define MAX_CMDS 64
typedef struct {
    int n;
    char name[MAX_CMDS][64];
    int leaf[MAX_CMDS];
} commands;

/* `heatvox [WORDS] --describe-options` (words: "" or "sdf"...). */
static char *describe(const char *words)
{
    char cmd[PATH_MAX + 128];
    int rc;
    snprintf(cmd, sizeof cmd, "'%s' %s --describe-options", bin, words);
    char *out = output(cmd, &rc);
    ck_assert_msg(rc == 0, "%s: exit %d", cmd, rc);
    return out;
}

static void add_commands(commands *c, const char *parent)
{
    char *d = describe(parent);
    for (char *line = strtok(d, "\n"); line; line = strtok(NULL, "\n")) {
        if (strncmp(line, "subcommand\t", 11))
            continue;
        const char *name = line + 11;
        ck_assert(c->n < MAX_CMDS);
        snprintf(c->name[c->n], sizeof c->name[0], "%.*s", (int)strcspn(name, "\t"), name);
        c->leaf[c->n] = 1;
        c->n++;
    }
    free(d);
}

static void list_commands(commands *c)
{
    c->n = 0;
    add_commands(c, "");
    for (int i = 0, top = c->n; i < top; i++) {
        char *d = describe(c->name[i]);
        const int parent = strstr(d, "\nsubcommand\t") != NULL;
        free(d);
        if (parent) {
            c->leaf[i] = 0;
            add_commands(c, c->name[i]);
        }
    }
}

/* Calls fn(name, the row's line, user) for every name of every option row of
 * command cmd. */
static void each_name(const char *cmd, void (*fn)(const char *, char *, void *), void *user)
{
    char *d = describe(cmd), *save = NULL;
    for (char *line = strtok_r(d, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
        if (strncmp(line, "option\t", 7))
            continue;
        char names[256];
        snprintf(names, sizeof names, "%.*s", (int)strcspn(line + 7, "\t"), line + 7);
        for (char *s = NULL, *n = strtok_r(names, "|", &s); n; n = strtok_r(NULL, "|", &s))
            fn(n, line, user);
    }
    free(d);
}

static void page_of(const char *cmd, char *path, size_t size)
{
    snprintf(path, size, "%s/man/heatvox-%s.1", build, cmd);
    for (char *p = strrchr(path, '/'); *p; p++)
        if (*p == ' ')
            *p = '-';
}

/* The page as text: rendered by groff where it is installed (its warnings
 * fail the test), else the roff source with its escapes of '-' and fonts
 * taken out. */
static char *page_text(const char *page)
{
    char cmd[PATH_MAX + 160];
    int rc;
    if (have("groff")) {
        snprintf(cmd, sizeof cmd, "groff -man -Tascii -P-cbou -rLL=250n -ww '%s' 2>&1", page);
        char *t = output(cmd, &rc);
        ck_assert_msg(rc == 0, "%s: exit %d", cmd, rc);
        ck_assert_msg(!strstr(t, "warning:") && !strstr(t, "error:"), "%s: %s", page, t);
        return t;
    }
    snprintf(cmd, sizeof cmd, "sed -e 's/\\\\-/-/g' -e 's/\\\\f[BIR]//g' '%s'", page);
    char *t = output(cmd, &rc);
    ck_assert_msg(rc == 0 && *t, "%s: cannot be read", page);
    return t;
}

typedef struct {
    const char *cmd, *where, *text;
    int missing;
} presence;

static void check_present(const char *name, char *row, void *user)
{
    presence *p = user;
    if (!has_word(p->text, name)) {
        printf("heatvox %s: %s is not in %s\n", p->cmd, name, p->where);
        p->missing++;
    }
}

START_TEST(every_option_of_every_command_should_be_in_its_man_page)
{
    commands c;
    list_commands(&c);
    ck_assert_int_ge(c.n, 10);
    int missing = 0;
    for (int i = 0; i < c.n; i++) {
        char page[PATH_MAX];
        page_of(c.name[i], page, sizeof page);
        ck_assert_msg(access(page, R_OK) == 0, "%s: no page (make man)", page);
        char *text = page_text(page);
        ck_assert_msg(strstr(text, "SYNOPSIS") && strstr(text, "EXIT STATUS"), "%s: %s", page,
                      text);
        presence p = {c.name[i], page, text, 0};
        if (c.leaf[i])
            each_name(c.name[i], check_present, &p);
        missing += p.missing;
        free(text);
    }
    ck_assert_msg(!missing, "%d option names are missing from the man pages", missing);
}
END_TEST

/* COMPREPLY, one word a line, of _heatvox for the words (a bash array's
 * contents) with the last one being completed, run in dir. */
static char *complete(const char *words)
{
    char script[PATH_MAX], cmd[PATH_MAX + 64];
    snprintf(script, sizeof script, "%s/complete.sh", dir);
    FILE *f = fopen(script, "w");
    ck_assert_ptr_nonnull(f);
    fprintf(f,
            "cd '%s' || exit 1\n. '%s/completion/heatvox' || exit 1\n"
            "COMP_WORDS=(%s)\nCOMP_CWORD=$((${#COMP_WORDS[@]} - 1))\n"
            "_heatvox || exit 1\nprintf '%%s\\n' \"${COMPREPLY[@]}\"\n",
            dir, build, words);
    fclose(f);
    snprintf(cmd, sizeof cmd, "bash --norc '%s'", script);
    int rc;
    char *out = output(cmd, &rc);
    ck_assert_msg(rc == 0, "completing %s: exit %d", words, rc);
    return out;
}

/* The words for a command's options: "heatvox bench solve -". */
static char *complete_options(const char *cmd)
{
    char words[256];
    snprintf(words, sizeof words, "heatvox %s -", cmd);
    return complete(words);
}

START_TEST(every_option_of_every_command_should_be_a_word_of_its_completion)
{
    commands c;
    list_commands(&c);
    int missing = 0;
    for (int i = 0; i < c.n; i++) {
        if (!c.leaf[i])
            continue;
        char *words = complete_options(c.name[i]);
        presence p = {c.name[i], "its completion", words, 0};
        each_name(c.name[i], check_present, &p);
        missing += p.missing;
        free(words);
    }
    ck_assert_msg(!missing, "%d option names are missing from the completion", missing);
}
END_TEST

static void expect_lines(const char *words, const char *want, const char *not_want)
{
    char *got = complete(words), list[1024];
    snprintf(list, sizeof list, "%s", want);
    for (char *s = NULL, *w = strtok_r(list, " ", &s); w; w = strtok_r(NULL, " ", &s))
        ck_assert_msg(has_line(got, w), "completing %s: no %s in\n%s", words, w, got);
    snprintf(list, sizeof list, "%s", not_want);
    for (char *s = NULL, *w = strtok_r(list, " ", &s); w; w = strtok_r(NULL, " ", &s))
        ck_assert_msg(!has_line(got, w), "completing %s: %s offered in\n%s", words, w, got);
    free(got);
}

/* Every choice of every option of a command is offered after it. */
typedef struct {
    const char *cmd;
    int options; /* with choices, so far */
} choices;

static void check_choices(const char *name, char *row, void *user)
{
    choices *ch = user;
    char f[7][256] = {{0}}, *save = NULL, copy[1024];
    snprintf(copy, sizeof copy, "%s", row);
    int k = 0;
    for (char *t = strtok_r(copy, "\t", &save); t && k < 7; t = strtok_r(NULL, "\t", &save))
        snprintf(f[k++], sizeof f[0], "%s", t);
    if (!strcmp(f[4], "-"))
        return;
    for (char *c = f[4]; *c; c++)
        if (*c == '|')
            *c = ' ';
    char words[512];
    snprintf(words, sizeof words, "heatvox %s %s ''", ch->cmd, name);
    expect_lines(words, f[4], "");
    ch->options++;
}

START_TEST(the_completion_should_offer_commands_choices_and_files)
{
    commands c;
    list_commands(&c);
    char want[2048] = "", bench[1024] = "";
    for (int i = 0; i < c.n; i++) {
        const char *sp = strchr(c.name[i], ' ');
        char *to = sp ? bench : want;
        size_t n = strlen(to);
        snprintf(to + n, sizeof want - n, "%s ", sp ? sp + 1 : c.name[i]);
    }
    expect_lines("heatvox ''", want, "");
    expect_lines("heatvox s", "sdf sdf2d slice", "batch");
    expect_lines("heatvox bench ''", bench, "");
    int nchoices = 0;
    for (int i = 0; i < c.n; i++)
        if (c.leaf[i]) {
            choices ch = {c.name[i], 0};
            each_name(c.name[i], check_choices, &ch);
            nchoices += ch.options;
        }
    ck_assert_msg(nchoices >= 10, "only %d options with choices", nchoices);
    char cmd[256];
    snprintf(cmd, sizeof cmd, "cd '%s' && touch a.obj B.STL b.vdb c.txt d.npy && mkdir sub", dir);
    ck_assert_int_eq(system(cmd), 0);
    expect_lines("heatvox sdf ''", "a.obj B.STL sub", "b.vdb c.txt d.npy");
    expect_lines("heatvox sdf a.obj -o ''", "b.vdb sub", "a.obj c.txt");
    expect_lines("heatvox sdf a.obj --npy d", "d.npy", "");
    expect_lines("heatvox sdf a.obj --mesh-out ''", "a.obj B.STL", "b.vdb");
    expect_lines("heatvox sdf a.obj --res ''", "", "a.obj --res");
    expect_lines("heatvox sdf a.obj --bbox 0 0 0 ''", "", "--res");
    expect_lines("heatvox distance --obstacles ''", "none b.vdb", "a.obj");
    expect_lines("heatvox make-scenes ''", "sub", "a.obj");
    expect_lines("heatvox bench solve --smoother j", "jacobi", "rbgs");
}
END_TEST

START_TEST(every_man_page_should_render_with_man)
{
    if (!have("man"))
        TL_SKIP("man is not installed (Debian's man-db)");
    commands c;
    list_commands(&c);
    char cmd[2 * PATH_MAX], page[PATH_MAX];
    for (int i = -1; i < c.n; i++) {
        if (i < 0)
            snprintf(page, sizeof page, "%s/man/heatvox.1", build);
        else
            page_of(c.name[i], page, sizeof page);
        snprintf(cmd, sizeof cmd, "MANWIDTH=100 MANPAGER=cat man -l '%s' 2>&1", page);
        int rc;
        char *text = output(cmd, &rc);
        ck_assert_msg(rc == 0, "%s: exit %d: %s", cmd, rc, text);
        ck_assert_msg(strstr(text, "NAME") && strstr(text, "SEE ALSO"), "%s: %s", page, text);
        free(text);
    }
}
END_TEST

int main(void)
{
    Suite *s = suite_create("man_completion");
    TCase *tc = tcase_create("core");
    tcase_set_timeout(tc, 300);
    tcase_add_checked_fixture(tc, setup, teardown);
    tcase_add_test(tc, every_option_of_every_command_should_be_in_its_man_page);
    tcase_add_test(tc, every_option_of_every_command_should_be_a_word_of_its_completion);
    tcase_add_test(tc, the_completion_should_offer_commands_choices_and_files);
    tcase_add_test(tc, every_man_page_should_render_with_man);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
