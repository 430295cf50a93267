#!/usr/bin/env python3
"""Section-size report for ELF files (32- or 64-bit, little-endian), without binutils.

Usage: elf_sizes.py ELF [ELF ...]

Sums the allocated sections by kind: .text* (code), .rodata* (constants), .data* (initialised
RAM, also stored in flash), .bss* (zeroed RAM) and everything else allocated (e.g. .stack,
.ARM.exidx) as `other`. Sizes in bytes and KiB.
"""
import struct
import sys

SHF_ALLOC = 0x2


def sections(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"\x7fELF":
        raise SystemExit(f"{path}: not an ELF file")
    is64 = data[4] == 2
    if data[5] != 1:
        raise SystemExit(f"{path}: big-endian ELF not supported")
    if is64:
        shoff, = struct.unpack_from("<Q", data, 0x28)
        shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x3A)
        fmt = "<IIQQQQIIQQ"
    else:
        shoff, = struct.unpack_from("<I", data, 0x20)
        shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x2E)
        fmt = "<IIIIIIIIII"
    hdrs = [struct.unpack_from(fmt, data, shoff + i * shentsize) for i in range(shnum)]
    stroff = hdrs[shstrndx][4]
    for name_off, _typ, flags, _addr, _off, size, *_ in hdrs:
        end = data.index(b"\0", stroff + name_off)
        yield data[stroff + name_off:end].decode(), flags, size


def kind(name):
    for k in ("text", "rodata", "data", "bss"):
        if name == "." + k or name.startswith("." + k + "."):
            return k
    return "other"


def main():
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    print(f"{'text':>10} {'rodata':>10} {'data':>10} {'bss':>10} {'other':>10}  file")
    for path in sys.argv[1:]:
        tot = dict.fromkeys(("text", "rodata", "data", "bss", "other"), 0)
        for name, flags, size in sections(path):
            if flags & SHF_ALLOC:
                tot[kind(name)] += size
        print(" ".join(f"{tot[k]:>10}" for k in tot) + f"  {path}")
        print(" ".join(f"{tot[k] / 1024:>9.1f}K" for k in tot))


if __name__ == "__main__":
    main()
