"""The FMU under test: its model description (the XML and fmpy's reading of it), its capability
flags and the binary this host can load, from a ``.fmu`` archive or an extracted folder."""
from __future__ import annotations

import copy
import io
import math
import platform
import zipfile
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

#: This host's platform folder and library suffix per FMI version (FMI 2.0 section 2.4 / FMI 3.0
#: "Platform tuple"), by (system, machine).
_PLATFORMS = {
    ("Linux", "x86_64"): ({2: "linux64", 3: "x86_64-linux"}, ".so"),
    ("Linux", "aarch64"): ({3: "aarch64-linux"}, ".so"),
    ("Darwin", "x86_64"): ({2: "darwin64", 3: "x86_64-darwin"}, ".dylib"),
    ("Darwin", "arm64"): ({3: "aarch64-darwin"}, ".dylib"),
    ("Windows", "AMD64"): ({2: "win64", 3: "x86_64-windows"}, ".dll"),
}


class BadInput(Exception):
    """The file given is not an FMU this host can check (exit status 2)."""


def extract(path: Path, dest: Path) -> Path:
    """``path`` (a .fmu or an extracted folder) as a folder: an archive is extracted into ``dest``."""
    if path.is_dir():
        if not (path / "modelDescription.xml").is_file():
            raise BadInput(f"{path}: a folder without modelDescription.xml is not an extracted FMU")
        return path
    if not path.is_file():
        raise BadInput(f"{path}: no such file or folder")
    if not zipfile.is_zipfile(path):
        raise BadInput(f"{path}: not an FMU (not a ZIP archive)")
    with zipfile.ZipFile(path) as archive:
        if "modelDescription.xml" not in archive.namelist():
            raise BadInput(f"{path}: not an FMU (no modelDescription.xml in the archive)")
        for name in archive.namelist():
            if Path(name).is_absolute() or ".." in Path(name).parts:
                raise BadInput(f"{path}: unsafe entry {name!r} in the archive")
        archive.extractall(dest)
    return dest


def number(text):
    """A numeric attribute (None when absent or not a number)."""
    if text is None:
        return None
    try:
        return float(text) if text.strip().lower() not in ("true", "false") else float(text.strip() == "true")
    except ValueError:
        return None


@dataclass(frozen=True)
class Variable:
    name: str
    vr: int
    type: str
    causality: str
    variability: str
    initial: str | None
    start: str | None
    min: float | None
    max: float | None
    scalar: bool

    def start_value(self):
        """The start value as the setter takes it (None if there is none)."""
        if self.start is None:
            return None
        if self.type == "String":
            return self.start.encode()
        if self.type == "Boolean":
            return self.start.strip() in ("true", "1")
        if self.type in ("Real", "Float64", "Float32"):
            return float(self.start)
        return int(self.start)

    def valid_value(self):
        """The start value moved into [min, max] (a start outside its range is static.start_range's
        finding; the dynamic checks set valid values)."""
        value = self.start_value()
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if self.max is not None and value > self.max:
                value = type(value)(self.max)
            if self.min is not None and value < self.min:
                value = type(value)(self.min)
        return value

    def bounded(self) -> bool:
        return any(b is not None and math.isfinite(b) for b in (self.min, self.max))


#: Default of ``initial`` when the attribute is absent (FMI 2.0 section 2.2.7, FMI 3.0 "Variable Attributes").
def default_initial(causality: str, variability: str) -> str | None:
    if causality in ("parameter", "structuralParameter"):
        return "exact"
    if causality == "calculatedParameter":
        return "calculated"
    if causality in ("input", "independent"):
        return None
    if variability == "constant":
        return "exact"
    return "calculated"


class Fmu:
    """An extracted FMU: ``dir``, ``version`` (2 or 3), ``root`` (the XML), ``md`` (fmpy's reading),
    ``variables``, the co-simulation capability flags and ``library`` for this host."""

    def __init__(self, folder: Path):
        from fmpy import read_model_description

        self.dir = Path(folder)
        xml = self.dir / "modelDescription.xml"
        try:
            self.root = etree.parse(str(xml)).getroot()
        except etree.XMLSyntaxError as exc:
            raise BadInput(f"{xml}: not well-formed XML ({exc})") from None
        version = self.root.get("fmiVersion", "")
        if version == "2.0":
            self.version = 2
        elif version.startswith("3."):
            self.version = 3
        else:
            raise BadInput(f"{xml}: fmiVersion {version!r}; this checker takes FMI 2.0 and 3.x")
        self.cs = self.root.find("CoSimulation")
        if self.cs is None:
            raise BadInput(f"{xml}: no CoSimulation element; this checker takes co-simulation FMUs only")
        # fmpy reads the variables; the model structure (static.model_structure's business, which
        # fmpy's reader cannot survive when it names unknown variables) is left out of its copy
        variables_only = copy.deepcopy(self.root)
        for structure in variables_only.findall("ModelStructure"):
            structure.clear()
        archive = io.BytesIO()
        with zipfile.ZipFile(archive, "w") as z:  # fmpy reads a file-like object as an archive
            z.writestr("modelDescription.xml", etree.tostring(variables_only))
        try:
            self.md = read_model_description(archive, validate=False)
        except Exception as exc:  # fmpy raises whatever its parser meets
            raise BadInput(f"{xml}: fmpy cannot read it ({exc})") from None
        self.identifier = self.cs.get("modelIdentifier")
        self.variables = [self._variable(v) for v in self.md.modelVariables]
        self.library = self._library()

    def flag(self, name: str) -> bool:
        """A co-simulation capability flag (FMI 3.0 spells FMUstate as FMUState)."""
        if self.version == 3:
            name = name.replace("FMUstate", "FMUState")
        return self.cs.get(name, "false") == "true"

    def _variable(self, v) -> Variable:
        declared = v.declaredType
        low = v.min if v.min is not None else getattr(declared, "min", None)
        high = v.max if v.max is not None else getattr(declared, "max", None)
        kind = "Enumeration" if v.type == "Enumeration" else v.type
        return Variable(v.name, v.valueReference, kind, v.causality, v.variability,
                        v.initial or default_initial(v.causality, v.variability), v.start, number(low), number(high),
                        not v.dimensions)

    def _library(self) -> Path:
        found = _PLATFORMS.get((platform.system(), platform.machine()))
        folder = found[0].get(self.version) if found else None
        if folder is None:
            raise BadInput(f"FMI {self.version}.0 has no platform folder for {platform.system()} {platform.machine()}")
        library = self.dir / "binaries" / folder / f"{self.identifier}{found[1]}"
        if not library.is_file():
            raise BadInput(f"no binary for this platform: binaries/{folder}/{library.name} is not in the FMU")
        return library

    @property
    def step_size(self) -> float:
        experiment = self.root.find("DefaultExperiment")
        size = number(experiment.get("stepSize")) if experiment is not None else None
        return size if size is not None and size > 0 else 1e-3
