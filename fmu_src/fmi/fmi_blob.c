/*
 * The framing check of FMU-state blobs (fmi_blob.h) and the checksums it uses.
 */
#include "fmi_blob.h"

#include <stdio.h>
#include <string.h>

/* A reflected CRC of `width` (32 or 64) bits with polynomial `poly`, all ones initially and xored
 * with all ones at the end: CRC-32 (zlib) and CRC-64/XZ are two of them. */
static uint64_t reflected_crc(const unsigned char *p, size_t n, uint64_t poly, unsigned width) {
    const uint64_t ones = width == 64 ? ~0ull : (1ull << width) - 1u;
    uint64_t table[256];
    for (uint64_t i = 0; i < 256; ++i) {
        uint64_t c = i;
        for (int k = 0; k < 8; ++k) c = (c & 1u) ? poly ^ (c >> 1) : c >> 1;
        table[i] = c;
    }
    uint64_t crc = ones;
    for (size_t i = 0; i < n; ++i) crc = table[(crc ^ p[i]) & 0xFFu] ^ (crc >> 8);
    return crc ^ ones;
}

uint32_t fmi_crc32(const unsigned char *p, size_t n) { return (uint32_t)reflected_crc(p, n, 0xEDB88320u, 32); }

uint64_t fmi_crc64(const unsigned char *p, size_t n) { return reflected_crc(p, n, 0xC96C5795D7870F42ull, 64); }

/* The little-endian unsigned integer of `bytes` bytes at p. */
static uint64_t get_le(const unsigned char *p, size_t bytes) {
    uint64_t x = 0;
    for (size_t i = bytes; i-- > 0;) x = (x << 8) | p[i];
    return x;
}

/* The GUID field as text for a message: up to its first NUL, printable ASCII only. */
static void guid_text(const unsigned char *field, size_t bytes, char *out, size_t n) {
    size_t k = 0;
    for (size_t i = 0; i < bytes && field[i] != 0 && k + 1 < n; ++i) out[k++] = (field[i] >= 32 && field[i] < 127) ? (char)field[i] : '?';
    out[k] = '\0';
}

const char *fmi_blob_problem(const FmiBlobFormat *f, const unsigned char *p, size_t size, char *why, size_t n) {
    if (p == NULL || size < f->min_bytes) {
        snprintf(why, n, "truncated: %zu bytes, a state of this FMU has at least %zu", p ? size : 0, f->min_bytes);
        return why;
    }
    if (memcmp(p, f->magic, f->magic_bytes) != 0) {
        snprintf(why, n, "not a serialized state of this FMU (bad magic)");
        return why;
    }
    const uint32_t version = (uint32_t)get_le(p + f->version_at, 4);
    if (version != f->version) {
        snprintf(why, n, "format version %u; this FMU reads version %u%s%s", (unsigned)version, (unsigned)f->version,
                 f->version_note ? " " : "", f->version_note ? f->version_note : "");
        return why;
    }
    const uint64_t field = get_le(p + f->size_at, f->size_field_bytes);
    if (field > size || field + f->size_add != size) {
        snprintf(why, n, "truncated or padded: %zu bytes, its header says %llu", size,
                 (unsigned long long)(field > size ? field : field + f->size_add));
        return why;
    }
    const size_t body = size - f->crc_bytes;
    const uint64_t crc = f->crc_bytes == 8 ? fmi_crc64(p, body) : fmi_crc32(p, body);
    if (crc != get_le(p + body, f->crc_bytes)) {
        snprintf(why, n, "checksum mismatch: the state is corrupted");
        return why;
    }
    const size_t ours = strlen(f->guid);
    int same = ours < f->guid_bytes && memcmp(p + f->guid_at, f->guid, ours) == 0;
    for (size_t i = ours; same && i < f->guid_bytes; ++i) same = p[f->guid_at + i] == 0;
    if (!same) {
        char theirs[128];
        guid_text(p + f->guid_at, f->guid_bytes, theirs, sizeof theirs);
        if (strcmp(theirs, f->guid) == 0)
            snprintf(why, n, "the state's GUID field holds bytes after the GUID (this FMU writes it NUL-padded)");
        else
            snprintf(why, n, "the state was saved by another FMU or another build of this one (GUID %s; this FMU "
                     "is %s)", theirs, f->guid);
        return why;
    }
    return NULL;
}
