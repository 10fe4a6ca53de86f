/*
 * The framing of an FMU-state blob, checked the same way for every C FMU of the project (the
 * pythonfmu FMUs' guard, guard_state.c, and the native regulator, avr_state.c): its size, magic,
 * format version, the size its header declares, the checksum over everything before the last
 * bytes, and the GUID of the FMU that saved it.  What lies inside the frame is each FMU's own.
 */
#ifndef FMI_BLOB_H
#define FMI_BLOB_H

#include <stddef.h>
#include <stdint.h>

/* zlib's CRC-32 and CRC-64/XZ (reflected ECMA-182) of p[0..n-1]. */
uint32_t fmi_crc32(const unsigned char *p, size_t n);
uint64_t fmi_crc64(const unsigned char *p, size_t n);

typedef struct {
    const char *magic;         /* the first magic_bytes bytes */
    size_t magic_bytes;
    size_t version_at;         /* u32 format version (little endian) */
    uint32_t version;
    const char *version_note;  /* why another version is refused (appended to the reason), or NULL */
    size_t size_at;            /* the size field: u32 or u64 (size_field_bytes) ... */
    size_t size_field_bytes;
    size_t size_add;           /* ... plus size_add is the blob's whole size */
    size_t crc_bytes;          /* 4: CRC-32, 8: CRC-64/XZ, in the last bytes, over every byte before them */
    size_t guid_at;            /* the saving FMU's GUID, NUL-padded to guid_bytes */
    size_t guid_bytes;
    const char *guid;          /* this FMU's GUID (shorter than guid_bytes) */
    size_t min_bytes;          /* the smallest blob of this format (at least every field above) */
} FmiBlobFormat;

/* NULL if the blob p[0..size-1] is framed as format f says; else why not, written to why[n]. */
const char *fmi_blob_problem(const FmiBlobFormat *f, const unsigned char *p, size_t size, char *why, size_t n);

#endif
