"""The campaign folder: what is in it, who may write to it, and the streamed CSV.

    DIR/campaign.json     manifest: name, fingerprint of the samples, arms, columns
    DIR/campaign.toml     the campaign file as given (with extends, resolved into one file)
    DIR/samples/<id>.toml one scenario file per sample (python -m scenarios run it alone)
    DIR/runs/<id>/try<k>/<id>/  the run output of each execution (summary.json, csv, plots)
    DIR/campaign.csv      one row per sample x arm, appended (flush + fsync) per finished task
    DIR/campaign.md       the analysis, with its plots
    DIR/.lock, .tmp/, .dask/   the writer's lock, the runs' TMPDIR, Dask's worker space

The fingerprint is the SHA-256 of every sample's scenario text: a folder holds exactly
one campaign, and ``--resume`` continues it only when the samples are the same.
"""
from __future__ import annotations

import csv
import fcntl
import hashlib
import json
import logging
import os
import shutil
from pathlib import Path
from typing import Any, Iterable, Sequence

from fmu_src.core.avr_errors import AvrError
from scenarios.campaign.task import COMPLETE, METRICS

log = logging.getLogger(__name__)

CSV_NAME, MANIFEST_NAME, COPY_NAME, REPORT_NAME = "campaign.csv", "campaign.json", "campaign.toml", "campaign.md"
#: Columns that measure time, not results (they differ between identical runs).
TIMING_COLUMNS = ("wall_s", "task_wall_s")


class CampaignDirError(AvrError):
    """The output folder cannot take this campaign (it holds another one, or is in use)."""


def fingerprint(texts: dict[str, str]) -> str:
    h = hashlib.sha256()
    for sid in sorted(texts):
        h.update(f"{sid}\n{texts[sid]}\n".encode())
    return h.hexdigest()


def columns(factor_names: Sequence[str]) -> list[str]:
    return ["sample", "arm", *factor_names, "status", *METRICS, "task_wall_s", "run_dir", "error"]


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v) if isinstance(v, float) else str(v)


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def read_rows(path: Path, cols: Sequence[str]) -> list[dict[str, str]]:
    """The CSV's rows as text; a line cut short by a crash (wrong field count) is dropped."""
    if not path.is_file():
        return []
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None:
            return []
        if header != list(cols):
            missing = [c for c in cols if c not in header]
            extra = [c for c in header if c not in cols]
            raise CampaignDirError(
                f"{path}: the columns differ from this campaign's (missing: {', '.join(missing) or 'none'}; "
                f"not expected: {', '.join(extra) or 'none'}; written by another version of the campaign "
                "tool?); choose another --out")
        rows = [dict(zip(cols, r)) for r in reader if len(r) == len(cols)]
    return rows


def write_rows_atomic(path: Path, cols: Sequence[str], rows: Iterable[dict[str, Any]]) -> None:
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        w.writerows([_cell(r.get(c)) for c in cols] for r in rows)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


class CampaignDir:
    """An output folder opened for one campaign (locked while open)."""

    def __init__(self, root: Path, name: str, texts: dict[str, str], arms: Sequence[str],
                 factor_names: Sequence[str], analysis: dict[str, Any] | None = None):
        self.root = Path(root)
        self.name = name
        self.analysis = dict(analysis or {})  # the report's settings (verdict metric, replicas)
        self.texts = texts
        self.arms = list(arms)
        self.cols = columns(factor_names)
        self.fingerprint = fingerprint(texts)
        self._lock = None
        self._csv = None

    # ---- paths
    csv_path = property(lambda self: self.root / CSV_NAME)
    samples_dir = property(lambda self: self.root / "samples")
    runs_dir = property(lambda self: self.root / "runs")
    tmp_dir = property(lambda self: self.root / ".tmp")
    dask_dir = property(lambda self: self.root / ".dask")

    def sample_file(self, sid: str) -> Path:
        return self.samples_dir / f"{sid}.toml"

    # ---- opening
    def open(self, *, resume: bool, campaign_file: Path | None, campaign_text: str | None = None) -> None:
        """Claim the folder: refuse another campaign, or this one without ``resume``. The
        folder keeps ``campaign_text`` (a campaign resolved into one file), else a copy of
        ``campaign_file``."""
        self.root.mkdir(parents=True, exist_ok=True)
        self._lock = open(self.root / ".lock", "w")
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock.close()
            self._lock = None
            raise CampaignDirError(f"{self.root}: another campaign process is writing into this folder") from None
        try:
            manifest = self._check_contents(resume)
        except CampaignDirError:
            self.close()
            raise
        if manifest is None:
            self._create(campaign_file, campaign_text)
        elif self.analysis:  # resumed: the report follows the campaign file's settings now
            if any(manifest.get(k) != v for k, v in self.analysis.items()):
                self._write_manifest({**manifest, **self.analysis})
        self._rewrite(only_complete=True)
        self._csv = open(self.csv_path, "a", newline="")

    def _check_contents(self, resume: bool) -> dict[str, Any] | None:
        """The folder's manifest (None for an empty folder), if it may be opened."""
        manifest_path = self.root / MANIFEST_NAME
        if not manifest_path.is_file():
            others = [p.name for p in self.root.iterdir() if p.name != ".lock"]
            if others:
                raise CampaignDirError(f"{self.root}: not empty and holds no campaign ({', '.join(sorted(others)[:5])}"
                                       f"{', ...' if len(others) > 5 else ''}); choose another --out")
            return None
        try:
            manifest = json.loads(manifest_path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise CampaignDirError(f"{manifest_path}: unreadable ({exc}); choose another --out") from None
        if manifest.get("fingerprint") != self.fingerprint:
            raise CampaignDirError(
                f"{self.root} holds a different campaign ({manifest.get('name')!r}, {manifest.get('n_samples')} "
                f"samples, other sample scenarios); it is never overwritten: choose another --out")
        if not resume:
            raise CampaignDirError(f"{self.root} already holds this campaign ({self.name!r}): continue it with "
                                   "--resume, or choose another --out")
        return manifest

    def _create(self, campaign_file: Path | None, campaign_text: str | None) -> None:
        self.samples_dir.mkdir(exist_ok=True)
        for sid, text in self.texts.items():
            self.sample_file(sid).write_text(text)
        if campaign_text is not None:
            (self.root / COPY_NAME).write_text(campaign_text)
        elif campaign_file is not None:
            shutil.copyfile(campaign_file, self.root / COPY_NAME)
        self._write_manifest({"name": self.name, "fingerprint": self.fingerprint, "n_samples": len(self.texts),
                              "arms": self.arms, "columns": self.cols, **self.analysis})

    def _write_manifest(self, manifest: dict[str, Any]) -> None:
        tmp = self.root / (MANIFEST_NAME + ".tmp")
        tmp.write_text(json.dumps(manifest, indent=2) + "\n")
        os.replace(tmp, self.root / MANIFEST_NAME)  # written last: a half-created folder has none

    # ---- rows
    def rows(self) -> list[dict[str, str]]:
        return read_rows(self.csv_path, self.cols)

    def complete_samples(self) -> set[str]:
        """Samples whose every arm has a ``complete`` row."""
        done: dict[str, set[str]] = {}
        for r in self.rows():
            if r["status"] == COMPLETE:
                done.setdefault(r["sample"], set()).add(r["arm"])
        return {s for s, arms in done.items() if set(self.arms) <= arms}

    def _rewrite(self, *, only_complete: bool) -> None:
        """One row per sample x arm (the last written), in sample and arm order, atomically.

        ``only_complete`` (when a run starts) also drops the rows of samples that are not
        complete: those samples run again and get fresh rows.
        """
        keep_samples = self.complete_samples() if only_complete else set(self.texts)
        order = {sid: i for i, sid in enumerate(self.texts)}
        arm_order = {a: i for i, a in enumerate(self.arms)}
        latest: dict[tuple[str, str], dict[str, str]] = {}
        for r in self.rows():
            if r["sample"] in keep_samples and r["sample"] in order and r["arm"] in arm_order:
                latest[(r["sample"], r["arm"])] = r
        rows = sorted(latest.values(), key=lambda r: (order[r["sample"]], arm_order[r["arm"]]))
        write_rows_atomic(self.csv_path, self.cols, rows)

    def append(self, rows: Sequence[dict[str, Any]]) -> None:
        """Write one finished task's rows to disk now (append, flush, fsync)."""
        w = csv.writer(self._csv)
        w.writerows([_cell(r.get(c)) for c in self.cols] for r in rows)
        self._csv.flush()
        os.fsync(self._csv.fileno())

    def finish(self) -> None:
        """Sort the CSV (sample, arm order) and drop the scratch folders."""
        if self._csv is not None:
            self._csv.close()
            self._csv = None
            self._rewrite(only_complete=False)
        shutil.rmtree(self.tmp_dir, ignore_errors=True)
        shutil.rmtree(self.dask_dir, ignore_errors=True)

    def close(self) -> None:
        if self._csv is not None:
            self._csv.close()
            self._csv = None
        if self._lock is not None:
            self._lock.close()
            self._lock = None
