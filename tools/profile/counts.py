#!/usr/bin/env python3
"""Where a run's instructions go, by mipray module, source file and function, inlining resolved.

The deterministic counterpart of `shares.py`: it reads valgrind callgrind's per-instruction
counts instead of perf's timed samples, so two builds (or two repeat counts of one) compare
exactly on a VM whose timings drift. As in `shares.py`, each instruction of the binary is
charged to the innermost frame of its inline chain (`addr2line -i`) that lies in the
project's `src/` (outside `src/simd/`): the tile kernel is one function in the symbol table,
but its instructions are charged to the integrator, the texture filter, the walks, and so on.

Usage (needs valgrind and binutils' `addr2line`; the binary must carry line tables, as the
release profile's does):

    valgrind --tool=callgrind --dump-instr=yes --dump-line=no --compress-pos=no \\
        --compress-strings=no --callgrind-out-file=A mipray bench ... --repeats 1
    (the same with --repeats 2 into B)
    tools/profile/counts.py BINARY B [--minus A] [--plus C] [--per N] [--files N]
        [--functions N] [--lines FILE]

With `--minus A`, the counts of A are subtracted address by address (so one pass of the
bench is left: the load and set-up cancel); `--minus` and `--plus` may be given several
times (one pass of `paper` less one pass of `none`: `P2 --minus P1 --minus N2 --plus N1`). `--per N` also prints each figure divided by N
(for example the frame's shaded hits, or the rays of a class). Instructions outside the
binary (libm's `powf`, libc's `memset`, the kernel's are not counted by valgrind) are
listed as `outside the binary`; instructions in the binary with no project frame (a
dependency or standard-library function that was not inlined) as `not in src/`.
"""

import argparse
import collections
import os
import sys

# The inline chains and the frame a cost is charged to, as `shares.py` resolves them.
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from shares import charged_frame, inline_frames  # noqa: E402


def short_name(function):
    """A demangled name without generic arguments (`f<T, U>` becomes `f`); the `<impl ...>`
    and `<T as Trait>` parts of a path stay, with their own generic arguments dropped."""
    out = []
    # Per open `<`: whether what it encloses is dropped.
    dropped = []
    for i, ch in enumerate(function):
        inside_dropped = bool(dropped) and dropped[-1]
        if ch == "<":
            # After an identifier (or a closing `>`): generic arguments. After `::` or at
            # the start: a part of the path.
            after_name = i > 0 and (function[i - 1].isalnum() or function[i - 1] in "_>")
            dropped.append(inside_dropped or after_name)
            if not dropped[-1]:
                out.append(ch)
        elif ch == ">" and dropped:
            if not dropped.pop():
                out.append(ch)
        elif not inside_dropped:
            out.append(ch)
    return "".join(out)


def read_counts(path, binary):
    """Per address of `binary`, its own (exclusive) instruction count; and the count outside it."""
    name = os.path.realpath(binary)
    inside = collections.Counter()
    outside = 0
    current_object = None
    skip_next = False
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if skip_next:
                # The line after `calls=` carries the call's inclusive cost: the callee's
                # own lines count it already.
                skip_next = False
                continue
            if line.startswith("ob="):
                current_object = os.path.realpath(line[3:].strip())
                continue
            if line.startswith("calls="):
                skip_next = True
                continue
            if not line.startswith("0x"):
                continue
            fields = line.split()
            if len(fields) < 2:
                continue
            count = int(fields[1])
            if current_object == name:
                inside[int(fields[0], 16)] += count
            else:
                outside += count
    return inside, outside


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("binary", help="the binary callgrind ran")
    parser.add_argument("data", help="callgrind output (--dump-instr=yes --compress-pos=no)")
    parser.add_argument(
        "--minus", metavar="DATA", action="append", default=[], help="output to subtract"
    )
    parser.add_argument(
        "--plus", metavar="DATA", action="append", default=[], help="output to add"
    )
    parser.add_argument("--per", type=float, help="also divide each figure by this")
    parser.add_argument("--files", type=int, default=20, help="how many files to list")
    parser.add_argument("--functions", type=int, default=30, help="how many functions")
    parser.add_argument(
        "--lines",
        metavar="FILE",
        help="also list the busiest lines of the project files whose path contains FILE",
    )
    args = parser.parse_args()
    for path in [args.binary, args.data, *args.minus, *args.plus]:
        if not os.path.isfile(path):
            sys.exit(f"{path}: no such file")

    inside, outside = read_counts(args.data, args.binary)
    for sign, paths in ((-1, args.minus), (1, args.plus)):
        for path in paths:
            other, other_outside = read_counts(path, args.binary)
            for address, count in other.items():
                inside[address] += sign * count
            outside += sign * other_outside
    addresses = sorted(a for a, c in inside.items() if c != 0)
    if not addresses:
        sys.exit(f"{args.data}: no instructions of {args.binary} (was it run from this binary?)")
    # callgrind gives an object's addresses as its ELF's virtual addresses (for a
    # position-independent executable too), which is what addr2line takes.
    frames = inline_frames(args.binary, addresses)
    modules = collections.Counter()
    files = collections.Counter()
    functions = collections.Counter()
    lines = collections.Counter()
    for address in addresses:
        count = inside[address]
        charged = charged_frame(frames[address])
        if charged is None:
            modules["not in src/"] += count
            continue
        module, path, line, function = charged
        modules[module] += count
        files[path] += count
        functions[(path, short_name(function))] += count
        if args.lines and args.lines in path:
            lines[(line, short_name(function))] += count
    modules["outside the binary"] = outside
    total = sum(modules.values())

    def row(name, count):
        per = f" | {count / args.per:,.1f}" if args.per else ""
        return f"| {name} | {count / 1e6:,.1f} M{per} | {100 * count / total:.1f}% |"

    head = " | per" if args.per else ""
    rule = "---:|" if args.per else ""
    print(f"{total / 1e6:,.1f} M instructions")
    print()
    print(f"| module | instructions{head} | share |")
    print(f"|---|---:|{rule}---:|")
    for name, count in modules.most_common():
        print(row(name, count))
    print()
    print(f"| file | instructions{head} | share |")
    print(f"|---|---:|{rule}---:|")
    for name, count in files.most_common(args.files):
        print(row(name, count))
    print()
    print(f"| function (file) | instructions{head} | share |")
    print(f"|---|---:|{rule}---:|")
    for (path, function), count in functions.most_common(args.functions):
        print(row(f"`{function[-90:]}` ({path})", count))
    if args.lines:
        print()
        print(f"| line (function) | instructions{head} | share |")
        print(f"|---|---:|{rule}---:|")
        for (line, function), count in lines.most_common(args.functions):
            print(row(f"{line} (`{function[-60:]}`)", count))


if __name__ == "__main__":
    main()
