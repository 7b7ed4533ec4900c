#!/usr/bin/env python3
"""Where a profile's samples fall, by mipray module and source file, inlining resolved.

`perf report --sort srcfile` names a sample's innermost source line, which for inlined code
is often a standard-library file (a SIMD intrinsic, a slice index), so a module's share of
a frame is split over `core_arch/x86/avx.rs`, `slice/index.rs` and the like. This script
resolves each sampled address's inline chain with `addr2line -i` and charges the sample
to the innermost frame that lies in the project's `src/` (outside `src/simd/`, whose vector
type, prefetch hints and dispatch are charged to the code using them): an intrinsic
inlined into the texture filter counts as texture filtering, a glam operation inlined
into shading counts as shading.

Usage (needs `perf` and binutils' `addr2line`; the binary must carry line tables, as the
`bench` profile's does):

    perf record -F 2000 -o perf.data target/release/mipray render SCENE ...
    tools/profile/shares.py perf.data target/release/mipray [--files N] [--lines FILE]

Prints the share of all samples (every DSO, the kernel included) per module
(`src/<module>/`), then the N busiest project files (and with `--lines`, the busiest lines
of the matching files). Samples outside the binary are
counted as `outside the binary` (libm's `powf`, the kernel's page faults, ...); samples in
the binary with no project frame (a standard-library or dependency function that was not
inlined) as `not in src/`.
"""

import argparse
import collections
import os
import re
import subprocess
import sys


SRC = "/src/"
# Paths of the standard library (`/rustc/<hash>/library/...`) and of dependencies (cargo's
# registry and git checkouts), which also have `src/` directories.
NOT_PROJECT = ("/rustc/", "/library/", "/.cargo/", "index.crates.io", "/cargo/registry/")


# mipray's own building blocks, charged to the code that uses them like the standard
# library's: `simd/` (the 8-lane vector type, prefetch hints, the dispatch itself).
HELPERS = ("/src/simd/",)


def is_project_file(location):
    """Whether an addr2line location (`path:line`) is in mipray's own `src/`, outside the
    helper modules."""
    return (
        SRC in location
        and not any(part in location for part in NOT_PROJECT)
        and not any(part in location for part in HELPERS)
    )


def run(command, **kwargs):
    """`command`'s standard output; a clear exit when it fails or is missing."""
    try:
        return subprocess.run(command, capture_output=True, text=True, check=True, **kwargs).stdout
    except FileNotFoundError:
        sys.exit(f"{command[0]}: not found (install perf and binutils)")
    except subprocess.CalledProcessError as e:
        sys.exit(f"{' '.join(command)}: exit {e.returncode}: {e.stderr.strip()[:300]}")


def inline_frames(binary, addresses):
    """Per address of `binary` (its ELF virtual addresses), its inline chain, innermost
    first, as (function, `path:line`) pairs, from `addr2line -i`."""
    resolved = run(
        ["addr2line", "-i", "-a", "-f", "-C", "-e", binary],
        input="\n".join(hex(a) for a in addresses),
    ).splitlines()
    frames = collections.defaultdict(list)
    current, i = None, 0
    while i < len(resolved):
        if resolved[i].startswith("0x"):
            current = int(resolved[i], 16)
            i += 1
            continue
        location = resolved[i + 1] if i + 1 < len(resolved) else ""
        frames[current].append((resolved[i], location))
        i += 2
    return frames


def charged_frame(chain):
    """The frame of an inline chain (as `inline_frames` gives it) that its cost is charged
    to: (module, path under `src/`, `path:line`, function) of the innermost project frame,
    or None where the chain has none."""
    for function, location in chain:
        if is_project_file(location):
            line = location.rsplit(SRC, 1)[1].split(" ", 1)[0]
            path = line.split(":", 1)[0]
            parts = path.split("/")
            return (parts[0] if len(parts) > 1 else path), path, line, function
    return None


def text_mapping(data, binary):
    """(runtime start, file offset) of the binary's executable mapping, from the mmap events."""
    events = run(["perf", "script", "-i", data, "--show-mmap-events", "-F", "ip"])
    name = os.path.realpath(binary)
    pattern = re.compile(r"\[(0x[0-9a-f]+)\((0x[0-9a-f]+)\) @ (0x[0-9a-f]+) .*\]: r-xp (\S+)")
    for line in events.splitlines():
        m = pattern.search(line)
        if m and os.path.realpath(m.group(4)) == name:
            return int(m.group(1), 16), int(m.group(3), 16)
    sys.exit(f"{data}: no executable mapping of {binary} (was it recorded from this binary?)")


def offset_to_vaddr(binary):
    """The executable segments' (file offset, size, virtual address), from the ELF header."""
    headers = run(["readelf", "-lW", binary])
    segments = []
    for line in headers.splitlines():
        fields = line.split()
        if fields[:1] == ["LOAD"] and "E" in fields[6:-1]:
            segments.append((int(fields[1], 16), int(fields[4], 16), int(fields[2], 16)))
    return segments


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="perf.data recorded from the binary")
    parser.add_argument("binary", help="the binary the profile was recorded from")
    parser.add_argument("--files", type=int, default=15, help="how many files to list")
    parser.add_argument(
        "--lines",
        metavar="FILE",
        help="also list the busiest lines of the project files whose path contains FILE",
    )
    args = parser.parse_args()
    for path, what in ((args.data, "perf data"), (args.binary, "binary")):
        if not os.path.isfile(path):
            sys.exit(f"{path}: no such file (the {what})")

    start, offset = text_mapping(args.data, args.binary)
    segments = offset_to_vaddr(args.binary)
    samples = run(["perf", "script", "-i", args.data, "-F", "ip,dso", "-G"])
    name = os.path.realpath(args.binary)
    in_binary = collections.Counter()
    total = 0
    for line in samples.splitlines():
        fields = line.split()
        if len(fields) < 2:
            continue
        total += 1
        if os.path.realpath(fields[1].strip("()")) != name:
            continue
        file_offset = int(fields[0], 16) - start + offset
        for seg_offset, size, vaddr in segments:
            if seg_offset <= file_offset < seg_offset + size:
                in_binary[file_offset - seg_offset + vaddr] += 1
                break
    if total == 0:
        sys.exit(f"{args.data}: no samples")
    if not in_binary:
        sys.exit(f"{args.data}: none of its {total} samples is in {args.binary}")

    frames = inline_frames(args.binary, sorted(in_binary))
    modules = collections.Counter()
    files = collections.Counter()
    lines = collections.Counter()
    for address, count in in_binary.items():
        charged = charged_frame(frames[address])
        if charged is None:
            modules["not in src/"] += count
            continue
        module, path, line, function = charged
        modules[module] += count
        files[path] += count
        if args.lines and args.lines in path:
            lines[(line, function)] += count
    modules["outside the binary"] = total - sum(in_binary.values())

    print(f"{total} samples, {sum(in_binary.values())} in {args.binary}")
    print()
    print("| module | samples | share |")
    print("|---|---:|---:|")
    for module, count in modules.most_common():
        print(f"| {module} | {count} | {100 * count / total:.1f}% |")
    print()
    print("| file | samples | share |")
    print("|---|---:|---:|")
    for path, count in files.most_common(args.files):
        print(f"| {path} | {count} | {100 * count / total:.1f}% |")
    if args.lines:
        print()
        print("| line | function | samples | share |")
        print("|---|---|---:|---:|")
        for (line, function), count in lines.most_common(args.files):
            print(f"| {line} | `{function[:60]}` | {count} | {100 * count / total:.1f}% |")


if __name__ == "__main__":
    main()
