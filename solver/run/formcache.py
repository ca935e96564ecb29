"""An in-process memo in front of FFCx's disk cache of compiled forms.

Every ``fem.form`` of dolfinx 0.5.2 asks FFCx for its compiled module. FFCx finds it in its
disk cache (``~/.cache/fenics``) through an ``importlib`` finder whose directory cache it
invalidates each time, so every form of every model build lists the whole cache directory, a
cost that grows with the cache (figures: docs/developer/design-notes.md). A model built many
times in one process (the pilot runs and adapted meshes of a tolerance run, the studies, the
tests) asks for the same modules again. This memo
keeps each module found in the disk cache for the process, keyed by everything FFCx's own
lookup is keyed by (the module's name, which is the forms' signature and the compiler
parameters, the object names and the cache directory). A module FFCx has not compiled yet
goes the usual way; once compiled and loaded, it is kept too.

The first lookup of a module in a process opens its file by name (:func:`_direct`) instead of
listing the cache directory, which a CLI run's start-up would otherwise pay once per module.

A compile is quiet: FFCx's JIT builds the module with distutils, which logs four lines a module (the gcc command
lines) to the root logger at INFO and sets the root logger's level to INFO, and ``import ffcx`` gave the root
logger a stderr handler: 24 lines on stderr for a model's six contact forms. Records below WARNING logged during
a compile are dropped, and what gcc writes to the process's stderr held back (written out if the compile fails),
unless :func:`show_compiler_output` (``solver run --verbose``) asked for them.
"""

from __future__ import annotations

import contextlib
import importlib.machinery
import importlib.util
import logging
import os
import sys
import tempfile
from pathlib import Path

import ffcx
import ffcx.codegeneration.jit as ffcx_jit
import ffcx.parameters

_disk_lookup = ffcx_jit.get_cached_module
_found: dict[tuple, tuple] = {}


def _lookup(module_name: str, object_names: list[str], cache_dir: Path | str, timeout: int):
    """FFCx's ``get_cached_module``, answered from memory for a module already found in this process."""
    key = (module_name, tuple(object_names), str(cache_dir))
    hit = _found.get(key)
    if hit is not None:
        return hit
    objects, module = _direct(module_name, object_names, cache_dir) or _disk_lookup(module_name, object_names,
                                                                                  cache_dir, timeout)
    if objects is not None:  # found on disk (None: not compiled yet; FFCx compiles it now)
        _found[key] = (objects, module)
    return objects, module


def _direct(module_name: str, object_names: list[str], cache_dir: Path | str) -> tuple | None:
    """A module FFCx has finished compiling into ``cache_dir``, loaded from its file; None if it is not there.

    What FFCx's ``get_cached_module`` does once it has the module (the ``.c.cached`` mark says the compile
    finished; the file is ``module_name`` + the first extension suffix present, as its ``FileFinder`` looks them
    up), without the finder's listing of the whole directory. Anything else (not compiled yet, being compiled by
    another process, a mark without its library) goes to FFCx's own lookup, which waits, compiles or raises."""
    cache = Path(cache_dir)
    if not (cache / f"{module_name}.c.cached").exists():
        return None
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = cache / f"{module_name}{suffix}"
        if path.is_file():
            loader = importlib.machinery.ExtensionFileLoader(module_name, str(path))
            spec = importlib.util.spec_from_file_location(module_name, path, loader=loader)
            module = importlib.util.module_from_spec(spec)
            loader.exec_module(module)
            return [getattr(module.lib, name) for name in object_names], module
    return None


_load = ffcx_jit._load_objects


def _loaded(cache_dir, module_name: str, object_names: list[str]):
    """FFCx's ``_load_objects`` (after a compile, and inside a disk lookup), kept in the memo: on a cold cache the
    modules compiled by the first build are then not looked up on disk again by the second."""
    objects, module = _load(cache_dir, module_name, object_names)
    _found[(module_name, tuple(object_names), str(cache_dir))] = (objects, module)
    return objects, module


_compile = ffcx_jit._compile_objects
_show = {"compiler": False}
compilations = {"count": 0}  # C modules compiled by this process (for tests and sweeps: a new value compiles none)


def show_compiler_output(on: bool = True) -> None:
    """Let the form compiler's build log (distutils' gcc command lines, FFCx's INFO) through to the logging
    handlers (off by default)."""
    _show["compiler"] = bool(on)


class _BelowWarning(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno >= logging.WARNING


def _compile_quietly(*args, **kwargs):
    """FFCx's ``_compile_objects``, counted, its INFO and DEBUG records dropped and what gcc itself writes to the
    process's stderr (its warnings on the generated C) held back, unless asked for; a failed compile lets through
    what gcc said."""
    compilations["count"] += 1
    if _show["compiler"]:
        return _compile(*args, **kwargs)
    root, quiet = logging.getLogger(), _BelowWarning()
    targets = [root, *root.handlers]  # the root logger's own records (distutils), and what reaches its handlers
    for t in targets:
        t.addFilter(quiet)
    try:
        with _stderr_held() as said:
            try:
                return _compile(*args, **kwargs)
            except BaseException:
                said.append(True)  # keep what gcc wrote: it says why
                raise
    finally:
        for t in targets:
            t.removeFilter(quiet)


@contextlib.contextmanager
def _stderr_held():
    """File descriptor 2 into a temporary file for the block; its text is dropped, or written back to stderr when
    the block appended to the yielded list (a failure)."""
    flag: list[bool] = []
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no stderr to hold (a closed descriptor): nothing to do
        yield flag
        return
    with tempfile.TemporaryFile(mode="w+b") as fh:
        os.dup2(fh.fileno(), 2)
        try:
            yield flag
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            if flag:
                fh.seek(0)
                sys.stderr.write(fh.read().decode(errors="replace"))


_merge = ffcx.parameters.get_parameters
_merged: dict[tuple, dict] = {}


def _parameters(priority_parameters: dict | None = None) -> dict:
    """FFCx's ``get_parameters`` (a copy of the merged values), kept per ``priority_parameters``: FFCx formats the
    whole merged table with ``pprint`` for an INFO record on every call, whatever the log level, three times per
    ``fem.form`` (a fifth of a small tolerance plan's time went there). The files it merges are read once per
    process by FFCx itself, so the values are the same on every call."""
    key = tuple(sorted((k, repr(v)) for k, v in (priority_parameters or {}).items()))
    hit = _merged.get(key)
    if hit is None:
        hit = _merged[key] = _merge(priority_parameters)
    else:
        ffcx.parameters.logger.setLevel(hit["verbosity"])  # what FFCx's call also does
    return dict(hit)


def install() -> None:
    """Put the memo in front of FFCx's lookup and loader, and the quiet compile (once per process; idempotent)."""
    ffcx_jit.get_cached_module = _lookup
    ffcx_jit._load_objects = _loaded
    ffcx_jit._compile_objects = _compile_quietly
    ffcx.parameters.get_parameters = _parameters
    ffcx.get_parameters = _parameters


def kept() -> int:
    """How many modules the memo holds (for tests)."""
    return len(_found)
