"""Reproducible FMU archives: sorted entries, fixed timestamps, content-derived GUIDs."""
from __future__ import annotations

import hashlib
import io
import uuid
import zipfile
from pathlib import Path

#: Fixed zip timestamp (the earliest a zip can hold) so builds are byte-identical.
ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)
#: Highest zlib compression level: the smallest archive, and deterministic for the same input.
ZIP_COMPRESS_LEVEL = 9
ZIP_CREATE_SYSTEM_UNIX = 3
EXECUTABLE_MODE, FILE_MODE = 0o755, 0o644
GUID_NAMESPACE = uuid.UUID("6f1c2a52-1d0e-4c59-9a57-4a7f2a1b0c01")
#: The GUID written into a model description before the content hash (and so the GUID) is known.
PLACEHOLDER_GUID = "{00000000-0000-0000-0000-000000000000}"


def read_entries(path: Path) -> dict[str, bytes]:
    """Every file (not folder) of the zip archive ``path``, by name."""
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist() if not name.endswith("/")}


def write_zip(entries: dict[str, bytes], path: Path, *, compress: bool = True) -> None:
    """Write ``entries`` to the archive ``path`` (replaced atomically) in sorted order with fixed
    timestamps and modes, so that the same entries always give the same bytes.  ``compress=False``
    stores them: for a draft that is read back and written again (the build's FMU before its
    reference results go in), whose final bytes are the same either way."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name in sorted(entries):
            info = zipfile.ZipInfo(name, date_time=ZIP_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
            info.create_system = ZIP_CREATE_SYSTEM_UNIX
            info.external_attr = (EXECUTABLE_MODE if name.endswith(".so") else FILE_MODE) << 16
            archive.writestr(info, entries[name], compresslevel=ZIP_COMPRESS_LEVEL if compress else None)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_bytes(buffer.getvalue())
    tmp.replace(path)


def content_guid(digest, entries: dict[str, bytes], *, prefix: str = "", skip=()) -> str:
    """``{uuid5}`` of ``digest`` (a hashlib object already fed whatever else counts) updated
    with every entry but those in ``skip``, by sorted name; ``prefix`` keeps two FMUs of
    identical content apart."""
    for name in sorted(entries):
        if name not in skip:
            digest.update(name.encode() + b"\0" + entries[name])
    return "{" + str(uuid.uuid5(GUID_NAMESPACE, prefix + digest.hexdigest())) + "}"


def sha256_of(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
