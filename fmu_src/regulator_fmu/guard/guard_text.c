/*
 * Strings the host passes in: UTF-8 validation with a length bound, the resource
 * location URI, and number formatting for messages.
 */
#define _GNU_SOURCE
#include <ctype.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "guard.h"

int utf8_valid(const char *s, size_t max_bytes, size_t *len) {
    const unsigned char *p = (const unsigned char *)s;
    size_t i = 0;
    while (i <= max_bytes) {
        unsigned c = p[i];
        if (c == 0) {
            if (len) *len = i;
            return 1;
        }
        size_t n;  /* continuation bytes */
        unsigned lo = 0x80, hi = 0xBF;  /* allowed range of the first continuation byte */
        if (c < 0x80) n = 0;
        else if (c >= 0xC2 && c <= 0xDF) n = 1;
        else if (c == 0xE0) { n = 2; lo = 0xA0; }              /* no overlongs */
        else if (c == 0xED) { n = 2; hi = 0x9F; }              /* no UTF-16 surrogates */
        else if (c >= 0xE1 && c <= 0xEF) n = 2;
        else if (c == 0xF0) { n = 3; lo = 0x90; }              /* no overlongs */
        else if (c >= 0xF1 && c <= 0xF3) n = 3;
        else if (c == 0xF4) { n = 3; hi = 0x8F; }              /* nothing above U+10FFFF */
        else return 0;
        for (size_t k = 1; k <= n; ++k) {
            unsigned d = p[i + k];  /* a NUL here fails the range test, so we never read past it */
            if (d < (k == 1 ? lo : 0x80) || d > (k == 1 ? hi : 0xBF)) return 0;
        }
        i += n + 1;
    }
    return 0;  /* longer than max_bytes (or not terminated within it) */
}

const char *string_problem(const char *s, size_t max_bytes) {
    if (s == NULL) return "is NULL";
    if (!utf8_valid(s, max_bytes, NULL)) {
        size_t i = 0;
        while (i <= max_bytes && s[i] != '\0') ++i;
        return i > max_bytes ? "is too long (or not NUL-terminated)" : "is not valid UTF-8";
    }
    return NULL;
}

void format_double(double x, char *out, size_t size) {
    if (isnan(x)) {
        snprintf(out, size, "nan");
        return;
    }
    int precision = 1;
    for (; precision < 17; ++precision) {
        snprintf(out, size, "%.*g", precision, x);
        if (strtod(out, NULL) == x) break;
    }
    /* whole numbers below 1e17 without an exponent: 50, not 5e+01 */
    double magnitude = fabs(x);
    if (isfinite(x) && magnitude >= 1.0 && magnitude < 1e17) {
        int digits = (int)floor(log10(magnitude)) + 1;
        if (digits > precision) precision = digits;
    }
    snprintf(out, size, "%.*g", precision, x);
}

static int hex_value(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    c = (char)tolower((unsigned char)c);
    return (c >= 'a' && c <= 'f') ? c - 'a' + 10 : -1;
}

/* The path part of a file URI (RFC 8089: file:///p, file:/p, file://localhost/p), or NULL. */
static const char *uri_path(const char *uri, char *why, size_t why_size) {
    if (strncasecmp(uri, "file:", 5) != 0) {
        snprintf(why, why_size, "only file: URIs are supported (file:///absolute/path/resources)");
        return NULL;
    }
    const char *rest = uri + 5;
    if (strncmp(rest, "//", 2) == 0) {  /* an authority: empty or localhost */
        rest += 2;
        if (strncasecmp(rest, "localhost", 9) == 0 && (rest[9] == '/' || rest[9] == '\0')) rest += 9;
        if (rest[0] != '/') {
            snprintf(why, why_size, "the URI names a remote host; only local files (file:///..., "
                     "file://localhost/...) can be loaded");
            return NULL;
        }
    }
    if (rest[0] != '/') {
        snprintf(why, why_size, "the URI's path must be absolute (file:///absolute/path/resources)");
        return NULL;
    }
    if (strpbrk(rest, "?#") != NULL) {
        snprintf(why, why_size, "the URI has a query or fragment ('?' or '#'; write them as %%3F, %%23)");
        return NULL;
    }
    return rest;
}

/* Decodes %XX escapes of src into dst (at least strlen(src) + 1 bytes); 0 on a bad escape or %00. */
static int percent_decode(const char *src, char *dst, char *why, size_t why_size) {
    size_t j = 0;
    for (size_t i = 0; src[i] != '\0'; ++i) {
        if (src[i] != '%') {
            dst[j++] = src[i];
            continue;
        }
        int hi = hex_value(src[i + 1]), lo = hi < 0 ? -1 : hex_value(src[i + 2]);
        if (hi < 0 || lo < 0) {
            snprintf(why, why_size, "invalid percent-escape at byte %zu of the URI's path", i);
            return 0;
        }
        if (hi == 0 && lo == 0) {
            snprintf(why, why_size, "the URI's path holds an escaped NUL (%%00) at byte %zu", i);
            return 0;
        }
        dst[j++] = (char)(hi * 16 + lo);
        i += 2;
    }
    dst[j] = '\0';
    return 1;
}

/* 1 if dir holds this FMU's Python slave (slavemodule.txt naming it, and the module file). */
static int is_our_resources(const char *dir, char *why, size_t why_size) {
    char file[PATH_MAX + 64], line[128] = "";
    snprintf(file, sizeof file, "%s/slavemodule.txt", dir);
    FILE *f = fopen(file, "r");
    if (f == NULL || fgets(line, sizeof line, f) == NULL) {
        if (f) fclose(f);
        snprintf(why, why_size, "the folder is not this FMU's resources folder (no readable slavemodule.txt)");
        return 0;
    }
    fclose(f);
    line[strcspn(line, "\r\n")] = '\0';
    if (strcmp(line, AVR_SLAVE_MODULE) != 0) {
        snprintf(why, why_size, "the folder holds another FMU's resources (slavemodule.txt does not name %s)",
                 AVR_SLAVE_MODULE);
        return 0;
    }
    struct stat st;
    snprintf(file, sizeof file, "%s/%s.py", dir, AVR_SLAVE_MODULE);
    if (stat(file, &st) != 0 || !S_ISREG(st.st_mode)) {
        snprintf(why, why_size, "the resources folder lacks %s.py", AVR_SLAVE_MODULE);
        return 0;
    }
    return 1;
}

char *resource_path(const char *uri, char *why, size_t why_size) {
    const char *problem = string_problem(uri, MAX_URI_BYTES);
    if (problem != NULL) {
        snprintf(why, why_size, "the URI %s", problem);
        return NULL;
    }
    const char *encoded = uri_path(uri, why, why_size);
    if (encoded == NULL) return NULL;
    char *decoded = malloc(strlen(encoded) + 1);
    if (decoded == NULL) {
        snprintf(why, why_size, "out of memory");
        return NULL;
    }
    char *path = NULL;
    struct stat st;
    if (!percent_decode(encoded, decoded, why, why_size)) {
        /* why is set */
    } else if (!utf8_valid(decoded, MAX_URI_BYTES, NULL)) {
        snprintf(why, why_size, "the decoded path is not valid UTF-8");
    } else if ((path = realpath(decoded, NULL)) == NULL || stat(path, &st) != 0 || !S_ISDIR(st.st_mode)) {
        snprintf(why, why_size, "the URI's path is not an existing folder");
    } else if (strstr(path, "%20") != NULL) {  /* pythonfmu 0.7.0 would turn it into a space */
        snprintf(why, why_size, "the resources folder's path contains the characters %%20, which pythonfmu "
                 "cannot load; move the FMU elsewhere");
    } else if (!utf8_valid(path, MAX_URI_BYTES, NULL)) {
        snprintf(why, why_size, "the resources folder's real path is not valid UTF-8");
    } else if (is_our_resources(path, why, why_size)) {
        free(decoded);
        return path;
    }
    free(decoded);
    free(path);
    return NULL;
}
