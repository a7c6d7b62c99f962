#!/usr/bin/env python3
"""Man pages and bash completion of heatvox, from the command itself.

Usage: man_completion.py HEATVOX MANDIR COMPLETION_FILE

`heatvox --describe-options` lists the commands, `heatvox CMD
--describe-options` the option rows its parser reads (tools/cli_describe.c)
and `heatvox CMD --help` the prose. Each command's page, heatvox-CMD.1 (a
benchmark's heatvox-bench-NAME.1), keeps the help text and lists under
OPTIONS every name of every row, described by the help's entry for it or,
where the help has none, by the row itself; the completion offers the same
names, the rows' choices and files by their extensions. Nothing is written
by hand, so neither can list an option the parser does not take, nor miss
one it does.
"""
import os
import re
import subprocess
import sys

ENTRY = re.compile(r"^( {1,8})(-\S.*?)(?: {2,}(\S.*))?$")
NAME = re.compile(r"(?<![\w-])(--?[A-Za-z0-9][\w-]*)")


def heatvox(binary, *args):
    r = subprocess.run([binary, *args], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("man_completion.py: %s %s: exit %d\n%s" % (binary, " ".join(args),
                                                            r.returncode, r.stderr))
    return r.stdout


def field(s):
    return "" if s == "-" else s


class Command:
    """One command's rows (its describe lines) and help text."""

    def __init__(self, binary, name, summary):
        self.name, self.summary = name, summary
        self.words, self.options, self.subcommands = None, [], []
        for line in heatvox(binary, *name.split(), "--describe-options").splitlines():
            f = line.split("\t")
            if f[0] == "subcommand":
                self.subcommands.append(Command(binary, f[1], f[2]))
            elif f[0] == "words":
                self.words = {"noun": f[1], "many": f[2] == "many", "files": field(f[3])}
            elif f[0] == "option":
                self.options.append({"names": f[1].split("|"), "kind": f[2], "arity": int(f[3]),
                                     "choices": [c for c in field(f[4]).split("|") if c],
                                     "files": field(f[5]), "needs": field(f[6])})
        self.help = heatvox(binary, *name.split(), "--help")

    @property
    def page(self):
        return "heatvox-" + self.name.replace(" ", "-")


# ---- roff ----

def esc(s):
    s = s.replace("\\", "\\e").replace("-", "\\-")
    return "\\&" + s if s[:1] in (".", "'") else s


def tag(s):
    """An entry's tag: option names bold, the rest as written."""
    parts = NAME.split(s)
    return "".join("\\fB%s\\fR" % esc(p) if k % 2 else esc(p) for k, p in enumerate(parts))


def paragraph(lines):
    """Lines of prose: filled when they start alike, kept as laid out otherwise."""
    indents = {len(l) - len(l.lstrip()) for l in lines}
    if len(indents) == 1 and max(indents) <= 4:
        text = " ".join(l.strip() for l in lines)
        return [".PP" if not max(indents) else ".IP", esc(text)]
    return [".PP", ".nf"] + [esc(l) for l in lines] + [".fi"]


def split_help(text):
    """(usage lines, body lines, exit lines) of a --help text."""
    lines = text.rstrip("\n").splitlines()
    usage, body, exits = [], [], []
    i = 0
    while i < len(lines) and lines[i].strip():
        usage.append(re.sub(r"^usage: ", "", lines[i]))
        i += 1
    while i < len(lines):
        if re.match(r"^(exit|[Ee]xit codes):", lines[i]):
            while i < len(lines) and lines[i].strip():
                exits.append(lines[i])
                i += 1
            continue
        body.append(lines[i])
        i += 1
    return usage, body, exits


def is_header(body, i):
    """A line such as "output:" over the entries it heads."""
    line = body[i]
    return bool(line) and not line[0].isspace() and line.endswith(":") and \
        i + 1 < len(body) and bool(ENTRY.match(body[i + 1]))


def blocks(body):
    """The body as ("entry", tag, text) and ("text", lines) blocks and ("header", line)."""
    out, i = [], 0
    while i < len(body):
        line = body[i]
        m = ENTRY.match(line)
        if m:
            indent, desc = len(m.group(1)), [m.group(3) or ""]
            i += 1
            while i < len(body) and body[i].strip() and not ENTRY.match(body[i]) and \
                    len(body[i]) - len(body[i].lstrip()) > indent:
                desc.append(body[i].strip())
                i += 1
            out.append(("entry", m.group(2).strip(), " ".join(d for d in desc if d)))
            continue
        if not line.strip():
            i += 1
            continue
        if is_header(body, i):
            out.append(("header", line[:-1]))
            i += 1
            continue
        para = []
        while i < len(body) and body[i].strip() and not ENTRY.match(body[i]) and \
                not is_header(body, i):
            para.append(body[i])
            i += 1
        out.append(("text", para))
    return out


def metavar(o):
    if o["arity"] == 0:
        return ""
    if o["kind"] == "choice":
        one = "|".join(o["choices"])
    elif o["files"]:
        one = "DIR" if o["files"] == "/" else "FILE"
    else:
        one = {"int": "N", "number": "X", "numbers": "X"}.get(o["kind"], "VALUE")
    return " " + " ".join([one] * o["arity"])


def row_text(o):
    """What a row says of itself, for an option the help text does not list."""
    said = []
    if o["needs"]:
        said.append("Takes %s." % o["needs"])
    if o["choices"] and not o["needs"]:
        said.append(("One of: %s." if o["kind"] == "choice" else "Or: %s.") %
                    ", ".join(o["choices"]))
    exts = [e for e in o["files"].split() if e.startswith(".")]
    if "/" in o["files"].split():
        said.append("A directory.")
    elif exts:
        said.append("A file ending in %s." % ", ".join(exts))
    elif o["files"]:
        said.append("A file.")
    if o["kind"] == "list":
        said.append("May be given more than once.")
    if o["kind"] == "flag" and o["names"] == ["-q", "-v"]:
        said.append("Quiet (no summary) or verbose (details on stderr).")
    return " ".join(said) or "See DESCRIPTION."


def options_section(cmd, body_blocks):
    out, covered = [], set()
    for b in body_blocks:
        if b[0] == "entry":
            covered.update(NAME.findall(b[1]))
    for b in body_blocks:
        if b[0] == "header":
            out += [".SS", esc(b[1])]
        elif b[0] == "entry":
            out += [".TP", tag(b[1]), esc(b[2]) if b[2] else "\\&"]
        else:
            out += paragraph(b[1])
    extra = []
    for o in cmd.options:
        missing = [n for n in o["names"] if n not in covered]
        if not missing:
            continue
        given = [n for n in o["names"] if n in covered]
        text = ("The same as %s." % ", ".join("\\fB%s\\fR" % esc(n) for n in given)) if given \
            else esc(row_text(o))
        extra += [".TP", tag(", ".join(missing) + metavar(o)), text]
    if extra:
        out += ([".SS", "More options"] if out else []) + extra
    return out


def man_page(cmd, version, see_also):
    usage, body, exits = split_help(cmd.help)
    bl = blocks(body)
    first = next((k for k, b in enumerate(bl) if b[0] in ("entry", "header")), len(bl))
    out = ['.TH "%s" 1 "" "heatvox %s" "heatvox manual"' % (cmd.page.upper(), version), ".nh", ".ad l",
           ".SH NAME", "%s \\- %s" % (esc(cmd.page), esc(cmd.summary)),
           ".SH SYNOPSIS", ".nf"] + [esc(u) for u in usage] + [".fi"]
    out += [".SH DESCRIPTION"]
    for b in bl[:first]:
        if not (cmd.subcommands and b[1][0] == "commands:"):
            out += paragraph(b[1])
    if cmd.subcommands:
        out += [".PP", "The benchmarks:" if cmd.name == "bench" else "The commands:"]
        for s in cmd.subcommands:
            out += [".TP", "\\fB%s\\fR(1)" % esc(s.page), esc(s.summary)]
    opts = options_section(cmd, bl[first:])
    if opts:
        out += [".SH OPTIONS"] + opts
    out += [".SH EXIT STATUS"]
    out += paragraph(exits) if exits else [
        ".PP", "0 success, 1 failure (unreadable or malformed input, I/O, a solver error), "
        "2 usage error."]
    out += [".SH SEE ALSO", ", ".join("\\fB%s\\fR(1)" % esc(p) for p in see_also if p != cmd.page)]
    return "\n".join(out) + "\n"


# ---- bash completion ----

def sh_quote(s):
    return "'" + s.replace("'", "'\\''") + "'"


COMPLETION_FN = r'''
# Files for a spec of _heatvox_files: "/" directories, "*" any file, else
# the extensions (".vdb .h5"); directories are always offered to descend.
_heatvox_filenames()
{
    local cur=$2 e
    local -a specs
    read -ra specs <<<"$1"
    local IFS=$'\n'
    COMPREPLY+=($(compgen -d -- "$cur"))
    for e in "${specs[@]}"; do
        case $e in
        /) ;;
        '*') COMPREPLY+=($(compgen -f -- "$cur")) ;;
        *)
            COMPREPLY+=($(compgen -f -X "!*$e" -- "$cur"))
            [[ $e == "${e^^}" ]] || COMPREPLY+=($(compgen -f -X "!*${e^^}" -- "$cur"))
            ;;
        esac
    done
    compopt -o filenames 2>/dev/null
    return 0
}

_heatvox()
{
    local cur=${COMP_WORDS[COMP_CWORD]} cmd first=2 k n opt key
    COMPREPLY=()
    if ((COMP_CWORD == 1)); then
        COMPREPLY=($(compgen -W "${_heatvox_sub[heatvox]} --help --version" -- "$cur"))
        return 0
    fi
    cmd=${COMP_WORDS[1]}
    if [[ -n ${_heatvox_sub[$cmd]+set} ]]; then
        if ((COMP_CWORD == 2)); then
            COMPREPLY=($(compgen -W "${_heatvox_sub[$cmd]} --help" -- "$cur"))
            return 0
        fi
        cmd="$cmd ${COMP_WORDS[2]}"
        first=3
    fi
    [[ -n ${_heatvox_opts[$cmd]+set} ]] || return 0
    # A value of the nearest option before the word, when it takes that many.
    for ((k = COMP_CWORD - 1; k >= first; k--)); do
        opt=${COMP_WORDS[k]}
        key="$cmd $opt"
        n=${_heatvox_arity[$key]-}
        [[ -n $n ]] || continue
        if ((COMP_CWORD - k <= n)); then
            [[ -z ${_heatvox_choices[$key]-} ]] ||
                COMPREPLY=($(compgen -W "${_heatvox_choices[$key]}" -- "$cur"))
            [[ -z ${_heatvox_files[$key]-} ]] || _heatvox_filenames "${_heatvox_files[$key]}" "$cur"
            return 0
        fi
        break
    done
    if [[ $cur == -* || -z ${_heatvox_words[$cmd]-} ]]; then
        COMPREPLY=($(compgen -W "${_heatvox_opts[$cmd]} --help" -- "$cur"))
    else
        _heatvox_filenames "${_heatvox_words[$cmd]}" "$cur"
    fi
    return 0
}
complete -F _heatvox heatvox
'''


def completion(top, cmds):
    out = ["# bash completion for heatvox. Generated by tools/man_completion.py from the",
           "# commands' option rows (heatvox COMMAND --describe-options): do not edit.",
           "declare -gA _heatvox_sub _heatvox_opts _heatvox_words _heatvox_arity \\",
           "    _heatvox_choices _heatvox_files"]
    out.append("_heatvox_sub[heatvox]=%s" % sh_quote(" ".join(c.name for c in top)))
    for c in cmds:
        if c.subcommands:
            out.append("_heatvox_sub[%s]=%s" % (sh_quote(c.name), sh_quote(
                " ".join(s.name.split()[-1] for s in c.subcommands))))
            continue
        names = [n for o in c.options for n in o["names"]]
        out.append("_heatvox_opts[%s]=%s" % (sh_quote(c.name), sh_quote(" ".join(names))))
        if c.words and c.words["files"]:
            out.append("_heatvox_words[%s]=%s" % (sh_quote(c.name), sh_quote(c.words["files"])))
        for o in c.options:
            for n in o["names"]:
                key = sh_quote(c.name + " " + n)
                if o["arity"]:
                    out.append("_heatvox_arity[%s]=%d" % (key, o["arity"]))
                if o["choices"]:
                    out.append("_heatvox_choices[%s]=%s" % (key, sh_quote(" ".join(o["choices"]))))
                if o["files"]:
                    out.append("_heatvox_files[%s]=%s" % (key, sh_quote(o["files"])))
    return "\n".join(out) + "\n" + COMPLETION_FN


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__.strip().splitlines()[2])
    binary, mandir, compfile = sys.argv[1:]
    version = heatvox(binary, "--version").split()[-1]
    top = [Command(binary, *line.split("\t")[1:3])
           for line in heatvox(binary, "--describe-options").splitlines()]
    cmds = [c for t in top for c in [t] + t.subcommands]
    pages = ["heatvox"] + [c.page for c in cmds]
    os.makedirs(mandir, exist_ok=True)
    for c in cmds:
        see = ["heatvox"] + ([p.page for p in top if p.name == c.name.split()[0]]
                             if " " in c.name else []) + [s.page for s in c.subcommands]
        with open(os.path.join(mandir, c.page + ".1"), "w") as f:
            f.write(man_page(c, version, see))
    with open(os.path.join(mandir, "heatvox.1"), "w") as f:
        f.write(man_page(RootPage(top, heatvox(binary, "--help")), version, pages))
    os.makedirs(os.path.dirname(compfile) or ".", exist_ok=True)
    with open(compfile, "w") as f:
        f.write(completion(top, cmds))


class RootPage:
    """heatvox(1): the command list and the driver's help."""

    def __init__(self, top, help_text):
        self.name, self.options, self.subcommands = "heatvox", [], top
        self.summary = "distance fields on volumetric grids with heat methods"
        self.help, self.page = help_text, "heatvox"


if __name__ == "__main__":
    main()
