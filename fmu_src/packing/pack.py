"""How a pythonfmu FMU carries its Python code: one package under a name private to the build.

pythonfmu 0.7.0's library, at every ``fmi2Instantiate`` (``PySlaveInstance.cpp``, ``findClass``):

* puts the FMU's ``resources/`` folder first on ``sys.path`` and never removes it;
* imports the module named in ``resources/slavemodule.txt`` with ``PyImport_ImportModule``, so a
  module of that name already in ``sys.modules`` (another build's, or a copy from a folder since
  deleted) is used as it is;
* runs the text of ``resources/<module>.py`` again in that module's namespace with separate
  locals, takes the name of the ``Fmi2Slave`` subclass bound there and returns the module's
  attribute of that name; it then releases one reference to the module's namespace that it
  never took (a borrowed ``PyModule_GetDict``), and leaks the class's MRO list.

So a slave script imported by a fixed name, with top-level ``import``s of the modules beside
it, shares its code with every other build loaded earlier in the process (pythonfmu issue #228),
re-creates its class at every instance (which the leaked MRO list keeps alive: memory grows
per instance), and breaks (the host crashes) when it re-runs after its folder was deleted.

Here every pythonfmu FMU is packed the same way (:func:`pack`):

* the slave and every project module it needs go into one package, ``resources/<lib_dir>/``,
  their project imports made package-relative (:func:`.vendor.vendor_modules`);
* the script pythonfmu loads is a generated entry module named ``<slave>_<id>``, ``<id>`` the
  sha256 of the package's content and of the entry template: different content gives different
  names, the same content the same ones.  On import it loads the package under the private name
  ``_<slave>_<id>``, every module at once (so the code never reads its folder again), and binds
  the slave class; when pythonfmu runs its text again it only hands back that class (the same
  class for every instance), gives back the reference pythonfmu releases, and removes the
  ``sys.path`` entry pythonfmu added.  If the package's folder is gone (``fmpy.simulate_fmu``
  deletes its extraction) the next instance loads the package again from its own folder.
"""
from __future__ import annotations

import hashlib
import string
from dataclasses import dataclass
from pathlib import Path

from fmu_src.packing import vendor

#: Hex digits of the content sha256 in the module names: 64 bits, no collision among any
#: number of builds a process will meet.
ID_CHARS = 16

ENTRY_TEMPLATE = string.Template('''\
"""pythonfmu's entry module of this FMU (written by build.py, fmu_src/packing/pack.py).

The FMU's code is the package in resources/$lib_dir/, imported under the private name
$package (a hash of its content), every module at once.  pythonfmu imports this module by
its name (slavemodule.txt) and, at every fmi2Instantiate, runs this text again in the
module's namespace with separate locals: that run only hands back the class loaded at import.
"""
if globals() is locals():  # imported
    import ctypes as _ctypes
    import importlib as _importlib
    import importlib.util as _importlib_util
    import logging as _logging
    import os as _os
    import sys as _sys

    _PACKAGE = "$package"
    _LIB = "$lib_dir"
    _SLAVE = "$slave"
    _CLASS = "$class_name"
    _MODULES = $modules
    #: pythonfmu 0.7.0's findClass releases one reference to this module's namespace that it
    #: never took, at every fmi2Instantiate; _instantiating takes one for it.
    _incref = _ctypes.PYFUNCTYPE(None, _ctypes.py_object)(("Py_IncRef", _ctypes.pythonapi))

    def _forget():
        for name in [n for n in _sys.modules if n == _PACKAGE or n.startswith(_PACKAGE + ".")]:
            del _sys.modules[name]

    def _loaded():
        """True if the package is imported and its folder still exists."""
        package = _sys.modules.get(_PACKAGE)
        return package is not None and _os.path.isdir(package.__path__[0])

    def _load(resources):
        """Import the package in resources/_LIB under _PACKAGE, every module of it now (none is
        imported later, so the code never reads its folder again); return the slave class."""
        root = _os.path.join(resources, _LIB)
        _forget()  # a copy whose folder is gone: its live instances keep their modules
        spec = _importlib_util.spec_from_file_location(_PACKAGE, _os.path.join(root, "__init__.py"),
                                                       submodule_search_locations=[root])
        package = _importlib_util.module_from_spec(spec)
        no_bytecode, _sys.dont_write_bytecode = _sys.dont_write_bytecode, True  # the folder stays as extracted
        _sys.modules[_PACKAGE] = package
        try:
            spec.loader.exec_module(package)
            for name in _MODULES:
                _importlib.import_module(_PACKAGE + "." + name)
        except BaseException:
            _forget()
            raise
        finally:
            _sys.dont_write_bytecode = no_bytecode
        return getattr(_sys.modules[_PACKAGE + "." + _SLAVE], _CLASS)

    def _claim_sys_path():
        """Remove sys.path[0] if it is this FMU's resources folder (pythonfmu puts it there at every
        fmi2Instantiate and never removes it) and return it; else None."""
        first = _sys.path[0] if _sys.path else None
        try:
            with open(_os.path.join(first, "slavemodule.txt"), encoding="utf-8") as f:
                ours = f.readline().strip() == __name__
        except (OSError, TypeError, ValueError):
            ours = False
        if not ours:
            return None
        del _sys.path[0]
        if first not in _sys.path:
            _sys.path_importer_cache.pop(first, None)
        return first

    def _instantiating():
        """The slave class, for pythonfmu's findClass; never raises (there it would crash the host)."""
        _incref(globals())
        try:
            resources = _claim_sys_path()
            if resources is not None and not _loaded():
                globals()[_CLASS] = _load(resources)
        except Exception:  # noqa: BLE001 - the class loaded at import serves
            _logging.getLogger(__name__).exception("cannot import %s from its new folder", _PACKAGE)
        return globals()[_CLASS]

    $class_name = (getattr(_sys.modules[_PACKAGE + "." + _SLAVE], _CLASS) if _loaded()
                   else _load(_os.path.dirname(_os.path.abspath(__file__))))
else:  # pythonfmu's findClass, at every fmi2Instantiate
    $class_name = _instantiating()
''')


@dataclass(frozen=True)
class Packed:
    """A staged pythonfmu FMU: ``entry`` is the script to give pythonfmu's builder, ``lib`` its
    one project folder (``resources/<lib.name>/`` in the FMU), ``module`` the entry's name (and
    ``slavemodule.txt``), ``package`` the private name the code is imported under."""

    entry: Path
    lib: Path
    module: str
    package: str


def content_id(lib: Path, *extra: bytes) -> str:
    """sha256 (first :data:`ID_CHARS` hex digits) of every file in ``lib`` (path and bytes) and ``extra``."""
    digest = hashlib.sha256()
    for path in sorted(p for p in lib.rglob("*") if p.is_file() and "__pycache__" not in p.parts):
        digest.update(path.relative_to(lib).as_posix().encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    for blob in extra:
        digest.update(blob)
    return digest.hexdigest()[:ID_CHARS]


def package_modules(lib: Path) -> list[str]:
    """Every module and subpackage in the package folder ``lib``, dotted, relative to it, sorted."""
    names = []
    for path in lib.rglob("*.py"):
        parts = path.relative_to(lib).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if parts:
            names.append(".".join(parts))
    return sorted(names)


def pack(stage: Path, slave_script: Path, class_name: str, lib_dir: str, project_files=(), fill=None) -> Packed:
    """Stage a pythonfmu FMU's code in ``stage``: the package ``stage/lib_dir`` (``slave_script``,
    ``project_files`` and the project modules they import; then ``fill(lib)`` adds data) and its
    entry module ``stage/<slave>_<id>.py`` binding ``class_name``."""
    lib = Path(stage) / lib_dir
    lib.mkdir(parents=True)
    vendor.vendor_modules(lib, [Path(slave_script), *map(Path, project_files)])
    if fill is not None:
        fill(lib)
    slave = ".".join(Path(slave_script).relative_to(vendor.REPO_ROOT).with_suffix("").parts)
    module = f"{Path(slave_script).stem}_{content_id(lib, ENTRY_TEMPLATE.template.encode(), class_name.encode())}"
    package = f"_{module}"
    text = ENTRY_TEMPLATE.substitute(package=package, lib_dir=lib_dir, slave=slave, class_name=class_name,
                                     modules=repr(tuple(package_modules(lib))))
    compile(text, module, "exec")  # a template error shows here, not inside a host
    entry = Path(stage) / f"{module}.py"
    entry.write_text(text, encoding="utf-8")
    return Packed(entry, lib, module, package)
