"""pythonfmu 0.7.0's linux64 library, fixed: its exit-time use-after-free patched out."""
from __future__ import annotations

import struct

#: pythonfmu 0.7.0's linux64 library frees its static ``pyState`` shared_ptr at exit and then
#: runs its destructor ``finalizePythonInterpreter``, which resets the same (already
#: destroyed) shared_ptr: a use-after-free that corrupts the heap at process exit (valgrind:
#: "Invalid read ... inside a block free'd"; a C host aborts every time, a Python host
#: sometimes).  The static destructor already releases the state, so the fix is to make
#: ``finalizePythonInterpreter`` return at once: after its ``endbr64``, a ``ret``.
EXIT_BUG_SYMBOL = b"finalizePythonInterpreter"
EXIT_BUG_PROLOGUE = bytes.fromhex("f30f1efa55")  # endbr64; push %rbp -- the 0.7.0 build we patch
EXIT_BUG_PATCH = bytes.fromhex("f30f1efac3")  # endbr64; ret
#: ELF64 constants (System V gABI): class and data of e_ident, header field offsets, section and segment types.
ELFCLASS64, ELFDATA2LSB = 2, 1
E_PHOFF_AT, E_PHENTSIZE_AT = 0x20, 0x36
SHT_DYNSYM, PT_LOAD = 11, 1
SYM_ENTRY = struct.Struct("<IBBHQQ")  # Elf64_Sym
SECTION_HEADER = struct.Struct("<IIQQQQIIQQ")  # Elf64_Shdr
PROGRAM_HEADER = struct.Struct("<IIQQQQQQ")  # Elf64_Phdr


def _elf_symbol_file_offset(data: bytes, symbol: bytes) -> int:
    """File offset of a dynamic symbol's code in an ELF64 little-endian shared library."""
    if data[:4] != b"\x7fELF" or data[4] != ELFCLASS64 or data[5] != ELFDATA2LSB:
        raise RuntimeError("pythonfmu's linux64 library is not an ELF64 little-endian file")
    e_phoff, e_shoff = struct.unpack_from("<QQ", data, E_PHOFF_AT)
    e_phentsize, e_phnum, e_shentsize, e_shnum = struct.unpack_from("<HHHH", data, E_PHENTSIZE_AT)
    sections = [SECTION_HEADER.unpack_from(data, e_shoff + i * e_shentsize) for i in range(e_shnum)]
    dynsym = next(s for s in sections if s[1] == SHT_DYNSYM)
    strtab = sections[dynsym[6]]  # sh_link: its string table
    value = None
    for off in range(dynsym[4], dynsym[4] + dynsym[5], SYM_ENTRY.size):
        st_name, _, _, _, st_value, _ = SYM_ENTRY.unpack_from(data, off)
        start = strtab[4] + st_name
        if data[start:data.index(b"\0", start)] == symbol:
            value = st_value
            break
    if value is None:
        raise RuntimeError(f"symbol {symbol.decode()} not found in pythonfmu's linux64 library")
    for i in range(e_phnum):
        p_type, _, p_offset, p_vaddr, _, p_filesz, _, _ = PROGRAM_HEADER.unpack_from(data, e_phoff + i * e_phentsize)
        if p_type == PT_LOAD and p_vaddr <= value < p_vaddr + p_filesz:
            return value - p_vaddr + p_offset
    raise RuntimeError(f"symbol {symbol.decode()} is not in a loaded segment")


def patch_pythonfmu_exit_bug(data: bytes) -> bytes:
    """pythonfmu 0.7.0's linux64 library without its use-after-free at process exit."""
    offset = _elf_symbol_file_offset(data, EXIT_BUG_SYMBOL)
    found = data[offset:offset + len(EXIT_BUG_PROLOGUE)]
    if found == EXIT_BUG_PATCH:
        return data
    if found != EXIT_BUG_PROLOGUE:
        raise RuntimeError(f"unexpected code at {EXIT_BUG_SYMBOL.decode()} ({found.hex()}): a pythonfmu build this "
                           "script does not know; check whether its exit-time use-after-free is fixed, "
                           "then update fmu_src/packing/pythonfmu_fix.py")
    return data[:offset] + EXIT_BUG_PATCH + data[offset + len(EXIT_BUG_PATCH):]
