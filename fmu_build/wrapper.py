"""pythonfmu's C++ wrapper (libpythonfmu-export.so) rebuilt from its sources with fixes.

The wrapper that pythonfmu 0.7.0 ships has these faults, each seen with the mill FMU:

1. ``findClass`` releases a reference it does not own (``Py_DECREF`` on the borrowed
   module dict from ``PyModule_GetDict``) at every fmi2Instantiate: the script module's
   namespace is freed under the interpreter once enough instances were made.
2. Every Python exception becomes fmi2Fatal, and the wrapper then releases the instance's
   Python objects while keeping the pointers: fmi2Terminate or fmi2FreeInstance after that
   uses freed memory (a segfault), and fmi2Error, which FMI 2.0 asks for where a call
   fails but the instance can go on (a state that cannot be deserialized, a
   communication point that does not match), can never be returned.
3. ``Fmi2Component`` destroys its logger before the slave, whose destructor still flushes
   log messages through it.
4. A compile error of the slave script calls ``Py_Finalize`` on the host's interpreter.
5. At process exit, the library's ELF destructor resets the static ``pyState``
   shared_ptr after that object's own C++ destructor has run (exit handlers run before the
   libraries' fini functions, and hosts' dlclose does not unload it): the control block is
   freed twice, and glibc aborts ("corrupted double-linked list") in a later free. Found
   with valgrind (invalid read in finalizePythonInterpreter of a block freed by the exit
   handlers); this is the abort hosts saw at exit.
6. Every fmi2Instantiate inserts the resources folder into ``sys.path`` again (leaking the
   string), and ``findClass`` leaks the MRO list, the reprs and their bytes of every class
   the script defines: the host's memory grew by about 2 kB per instantiate/free cycle.

Measured (``python -m fmu_build.exit_study``, 200 processes each loading three mill FMUs
in fmpy, stepping, freeing them and exiting normally): see docs/fmu.md.

pythonfmu 0.7.0's sdist carries no C++ sources, and its wrapper differs from 0.6.9's only
in ``SetupExperiment`` passing stop time and tolerance on to Python (which 0.7.0's
``Fmi2Slave.setup_experiment`` requires). So the sources are pythonfmu 0.6.9's sdist from
PyPI (fetched with pip, checked against a pinned sha256), brought to 0.7.0's interface and
fixed by the edits below, each required to match exactly once; then built with CMake and
the system's C++ compiler. The result is cached per source, edits and Python
(``$MILLFMU_WRAPPER_DIR``, else ``$XDG_CACHE_HOME/millfmu/pythonfmu-wrapper``, else
``~/.cache/millfmu/pythonfmu-wrapper``). Where any step is not possible (no compiler, no
CMake, no network, another pythonfmu version), :func:`fixed_wrapper` returns None with the
reason and ``build-fmu`` keeps pythonfmu's own wrapper, with a warning.
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import sysconfig
import tarfile
from pathlib import Path

#: The pythonfmu version whose Python side the rebuilt wrapper serves.
PYTHONFMU_VERSION = "0.7.0"
#: The sdist with the C++ sources (0.7.0's has none) and its sha256.
SOURCE_SDIST = "pythonfmu==0.6.9"
SOURCE_SHA256 = "13eab981d3c86704ab19b35ebcee9347b2dcc378bbe8d0b43c9ae1fe35bc9fa7"
EXPORT_DIR = "pythonfmu/pythonfmu-export"
#: Written into an FMU's resources: which wrapper it carries ("fixed" or "stock"). The
#: slave raises exceptions (-> fmi2Error) only under the fixed wrapper.
MARKER_FILE = "wrapper.txt"

#: (file, old, new): each ``old`` must occur exactly once in ``file``.
EDITS = (
    # 0.7.0's interface: setup_experiment(start_time, stop_time, tolerance), None if undefined.
    ("src/pythonfmu/PySlaveInstance.cpp",
     'py_safe_run([this, startTime](PyGILState_STATE gilState) {\n'
     '            auto f = PyObject_CallMethod(pInstance_, "setup_experiment", "(d)", startTime);',
     'py_safe_run([this, startTime, stop, tolerance](PyGILState_STATE gilState) {\n'
     '            PyObject* pyStop = stop ? PyFloat_FromDouble(*stop) : (Py_INCREF(Py_None), Py_None);\n'
     '            PyObject* pyTol = tolerance ? PyFloat_FromDouble(*tolerance) : (Py_INCREF(Py_None), Py_None);\n'
     '            auto f = PyObject_CallMethod(pInstance_, "setup_experiment", "(dOO)", startTime, pyStop, pyTol);\n'
     '            Py_DECREF(pyStop);\n'
     '            Py_DECREF(pyTol);'),
    # 1. The module dict is borrowed: never released here.
    ("src/pythonfmu/PySlaveInstance.cpp",
     "        PyErr_Print(); // Handle compilation error\n        Py_Finalize();\n        Py_DECREF(pGlobals);\n"
     "        Py_DECREF(pyModule);\n        Py_DECREF(pLocals);\n        Py_DECREF(pCode);\n",
     "        PyErr_Print(); // Handle compilation error\n"
     "        Py_DECREF(pyModule);\n        Py_DECREF(pLocals);\n"),
    ("src/pythonfmu/PySlaveInstance.cpp",
     "    Py_DECREF(pyModule);\n    Py_DECREF(pGlobals);\n",
     "    Py_DECREF(pyModule);\n"),
    # 2. A Python exception is an error of this call (fmi2Error); the instance keeps its
    #    Python objects and stays usable.
    ("src/pythonfmu/PySlaveInstance.cpp",
     "        const auto err = PyErr_Occurred();\n        if (err != nullptr) {\n            cleanPyObject();\n",
     "        const auto err = PyErr_Occurred();\n        if (err == nullptr) {\n"
     "            PyGILState_Release(gilState);\n"
     "            throw std::runtime_error(what + \": failed without a Python exception\");\n"
     "        }\n        {\n"),
    #    The slave's own refusal (an exception named FMUCallError) is logged as its message
    #    alone; any other exception with the call's name and its repr.
    ("src/pythonfmu/PySlaveInstance.cpp",
     '            oss << "Fatal py exception encountered: ";\n'
     '            oss << what << "\\n";\n'
     '            if (pExcValue != nullptr) {\n'
     '                PyObject* pRepr = PyObject_Repr(pExcValue);\n',
     '            PyErr_NormalizeException(&pExcType, &pExcValue, &pExcTraceback);\n'
     '            bool own = false;\n'
     '            if (pExcType != nullptr) {\n'
     '                PyObject* pName = PyObject_GetAttrString(pExcType, "__name__");\n'
     '                if (pName != nullptr) {\n'
     '                    own = PyUnicode_CompareWithASCIIString(pName, "FMUCallError") == 0;\n'
     '                    Py_DECREF(pName);\n'
     '                }\n'
     '                PyErr_Clear();\n'
     '            }\n'
     '            if (!own) {\n'
     '                oss << "Python exception: " << what << "\\n";\n'
     '            }\n'
     '            if (pExcValue != nullptr) {\n'
     '                PyObject* pRepr = own ? PyObject_Str(pExcValue) : PyObject_Repr(pExcValue);\n'),
    ("src/pythonfmu/PySlaveInstance.cpp",
     "            throw fatal_error(oss.str());",
     "            throw std::runtime_error(oss.str());"),
    # fmi2SetFMUstate's result was never released.
    ("src/pythonfmu/PySlaveInstance.cpp",
     'handle_py_exception("[_set_fmu_state] PyObject_CallMethod", gilState);\n            }\n',
     'handle_py_exception("[_set_fmu_state] PyObject_CallMethod", gilState);\n            }\n'
     "            Py_DECREF(f);\n"),
    # 6. Per fmi2Instantiate, the resources folder went into sys.path again (a longer list
    #    each time) and its string leaked; findClass leaked, per class of the script and per
    #    class of its MRO, the MRO list, the repr and its UTF-8 bytes (about 1.8 kB a cycle).
    ("src/pythonfmu/PySlaveInstance.cpp",
     "            int success = PyList_Insert(sys_path, 0, PyUnicode_FromString(resourceLocation().c_str()));\n",
     "            PyObject* pResources = PyUnicode_FromString(resourceLocation().c_str());\n"
     "            int success = pResources == nullptr ? -1\n"
     "                : (PySequence_Contains(sys_path, pResources) == 1 ? 0 : PyList_Insert(sys_path, 0, "
     "pResources));\n            Py_XDECREF(pResources);\n"),
    ("src/pythonfmu/PySlaveInstance.cpp",
     "                const char* className = PyBytes_AsString(PyUnicode_AsUTF8String(PyObject_Repr(pItem)));\n\n"
     "                std::string str(className);\n",
     "                PyObject* pRepr = PyObject_Repr(pItem);\n"
     "                PyObject* pReprBytes = pRepr != nullptr ? PyUnicode_AsUTF8String(pRepr) : nullptr;\n"
     "                std::string str(pReprBytes != nullptr ? PyBytes_AsString(pReprBytes) : \"\");\n"
     "                Py_XDECREF(pReprBytes);\n"
     "                Py_XDECREF(pRepr);\n"),
    ("src/pythonfmu/PySlaveInstance.cpp",
     "                    deepestFile = PyBytes_AsString(PyUnicode_AsUTF8String(key));\n",
     "                    PyObject* pKeyBytes = PyUnicode_AsUTF8String(key);\n"
     "                    deepestFile = PyBytes_AsString(pKeyBytes);\n"
     "                    Py_DECREF(pKeyBytes);\n"),
    ("src/pythonfmu/PySlaveInstance.cpp",
     "                    deepestChain = i;\n                }\n            }\n        }\n        "
     "Py_DECREF(pMroAttribute);\n",
     "                    deepestChain = i;\n                }\n            }\n            Py_DECREF(pMROList);\n      "
     "  }\n        Py_XDECREF(pMroAttribute);\n"),
    # 5. pyState's static destructor releases it; the fini function must not touch it again.
    ("src/pythonfmu/PySlaveInstance.cpp",
     "__attribute__((destructor)) void onLibraryUnload()\n{\n    finalizePythonInterpreter();\n}",
     "__attribute__((destructor)) void onLibraryUnload()\n{\n"
     "    // Nothing: pyState's own static destructor has released it by now.\n}"),
    # 3. The slave (whose destructor logs) goes before the logger.
    ("src/pythonfmu/fmi2.cpp",
     "    double lastSuccessfulTime{0};\n",
     "    ~Fmi2Component() { slave.reset(); }\n\n    double lastSuccessfulTime{0};\n"),
)
#: Changes with the edits or the build recipe: part of the cache key.
RECIPE_VERSION = "2"


def wrapper_dir() -> Path:
    env = os.environ.get("MILLFMU_WRAPPER_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "millfmu" / "pythonfmu-wrapper"


def _platform_dir() -> str | None:
    """pythonfmu's binaries folder for this machine (only linux64 is rebuilt here)."""
    if sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64") and sys.maxsize > 2**32:
        return "linux64"
    return None


def _key() -> str:
    h = hashlib.sha256()
    for part in (SOURCE_SHA256, RECIPE_VERSION, repr(EDITS), sysconfig.get_paths()["include"], sys.version):
        h.update(part.encode() + b"\0")
    return h.hexdigest()[:16]


def apply_edits(root: Path) -> None:
    """Apply :data:`EDITS` to the export sources under ``root``; RuntimeError if one does not match once."""
    for rel, old, new in EDITS:
        p = root / rel
        text = p.read_text()
        n = text.count(old)
        if n != 1:
            raise RuntimeError(f"{rel}: expected the text to fix once, found it {n} times: "
                               f"{old.splitlines()[0].strip()!r}")
        p.write_text(text.replace(old, new))


def _run(cmd, cwd=None):
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0:
        tail = "\n".join((r.stdout + r.stderr).strip().splitlines()[-15:])
        raise RuntimeError(f"{' '.join(map(str, cmd[:3]))} ... failed (exit status {r.returncode}):\n{tail}")
    return r


def _fetch_sources(tmp: Path) -> Path:
    """pythonfmu's sdist with the C++ sources, via pip; checked against SOURCE_SHA256."""
    # No retries and a short timeout: without a network the build falls back at once.
    _run([sys.executable, "-m", "pip", "download", "--quiet", "--retries", "0", "--timeout", "20", "--no-binary",
          ":all:",
          "--no-deps", "--dest", str(tmp), SOURCE_SDIST])
    (sdist,) = tmp.glob("pythonfmu-*.tar.gz")
    digest = hashlib.sha256(sdist.read_bytes()).hexdigest()
    if digest != SOURCE_SHA256:
        raise RuntimeError(f"{sdist.name}: sha256 {digest}, expected {SOURCE_SHA256}")
    with tarfile.open(sdist) as tar:
        members = [m for m in tar.getmembers() if f"/{EXPORT_DIR}/" in m.name and (m.isfile() or m.isdir())]
        tar.extractall(tmp / "src", members=members)
    (export,) = (tmp / "src").glob(f"*/{EXPORT_DIR}")
    return export


def _cmake() -> str | None:
    """CMake on PATH, else the one a Python environment brings (fmpy depends on the cmake package)."""
    return shutil.which("cmake") or shutil.which("cmake", path=str(Path(sys.executable).parent))


def build_wrapper(dest: Path, progress=None) -> Path:
    """Fetch, fix and build the wrapper into ``dest`` (a file); RuntimeError saying what
    failed. ``progress(text)``, when given, hears each step (about 40 s in all, once)."""
    from .leftovers import clean, tag, temp_dir

    say = progress or (lambda text: None)
    cmake = _cmake()
    if cmake is None:
        raise RuntimeError("no cmake found")
    if not any(shutil.which(c) for c in ("c++", "g++", "clang++")):
        raise RuntimeError("no C++ compiler (c++, g++, clang++) on PATH")
    say(f"building pythonfmu's C++ wrapper with millfmu's fixes (once, about 40 s; cached in {dest.parent})")
    with temp_dir("millfmu-wrapper-") as tmp:
        tmp = Path(tmp)
        say("  1/3 fetching pythonfmu's sources (pip download)")
        export = _fetch_sources(tmp)
        apply_edits(export)
        build = tmp / "build"
        include = sysconfig.get_paths()["include"]
        say("  2/3 configuring (cmake)")
        _run([cmake, "-S", str(export), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
              f"-DPython3_EXECUTABLE={sys.executable}", f"-DPython3_INCLUDE_DIR={include}"])
        say("  3/3 compiling (cmake --build)")
        _run([cmake, "--build", str(build), "-j", "2"])
        (lib,) = export.parent.glob("resources/binaries/*/libpythonfmu-export.so")
        dest.parent.mkdir(parents=True, exist_ok=True)
        clean(dest.parent, f".{dest.name}.")
        part = dest.with_name(tag(f".{dest.name}.") + "part")
        try:
            shutil.copy2(lib, part)
            part.replace(dest)
        finally:
            part.unlink(missing_ok=True)
    say("  done")
    return dest


#: Told each step of a first build of the wrapper (set by choose_wrapper's progress).
_progress = None


@functools.cache
def fixed_wrapper() -> tuple[Path | None, str]:
    """(path of the fixed wrapper for this machine, "") or (None, why it is not available);
    tried once per process. MILLFMU_STOCK_WRAPPER=1 keeps pythonfmu's own on purpose."""
    if os.environ.get("MILLFMU_STOCK_WRAPPER") == "1":
        return None, "MILLFMU_STOCK_WRAPPER=1"
    try:
        import pythonfmu
    except ImportError:
        return None, "pythonfmu is not installed"
    if pythonfmu.__version__ != PYTHONFMU_VERSION:
        return None, f"pythonfmu {pythonfmu.__version__} installed; the fix is made for {PYTHONFMU_VERSION}"
    plat = _platform_dir()
    if plat is None:
        return None, f"rebuilt only for linux64 (this is {sys.platform} {platform.machine()})"
    dest = wrapper_dir() / _key() / plat / "libpythonfmu-export.so"
    if dest.exists():
        return dest, ""
    try:
        return build_wrapper(dest, _progress), ""
    except (RuntimeError, OSError, ValueError, subprocess.SubprocessError) as e:
        return None, str(e)


_WARNED: set = set()


def choose_wrapper(log=None, progress=None) -> Path | None:
    """The fixed wrapper, or None (pythonfmu's own kept) with a warning through ``log``
    (default: stderr, once per process) saying why and what the FMU then cannot do.
    ``progress(text)`` hears the steps of a first build of the wrapper."""
    global _progress
    _progress = progress
    try:
        path, why = fixed_wrapper()
    finally:
        _progress = None
    if path is None and (log is not None or why not in _WARNED):
        _WARNED.add(why)
        msg = (f"warning: pythonfmu's own C++ wrapper kept ({why}): a Python exception in the FMU "
               f"would be fmi2Fatal, so refusals are logged errors with fmi2OK/fmi2Discard instead of fmi2Error, "
               f"and hosts may abort at exit; install a C++ compiler and CMake to get the fixed wrapper")
        (log or (lambda m: print(m, file=sys.stderr)))(msg)
    return path


#: Folders of pythonfmu's binaries that the FMUs do not carry: its win64 wrapper is the stock
#: one (none of the fixes above, which are built and tested for linux64 only), and shipping
#: it would make the same FMU behave differently on Windows (fmi2Fatal where Linux answers
#: fmi2Error, the leaks, the double release at exit) without anything saying so.
DROPPED_PLATFORMS = ("win64",)
#: What the build says about it (build-fmu's output, docs/fmu.md).
PLATFORM_NOTE = ("x86_64 Linux only (binaries/linux64): pythonfmu's Windows wrapper lacks millfmu's fixes, "
                 "and none is built or tested for Windows")


def fmi2_replacements(ident: str, wrapper: Path | None) -> dict:
    """Entries to replace in a pythonfmu FMU of model identifier ``ident`` (for
    ``fmu_build.build.write_fmu``): the linux64 binary by ``wrapper`` when given, the
    binaries of :data:`DROPPED_PLATFORMS` dropped, and the resources' :data:`MARKER_FILE`
    naming the wrapper the FMU carries."""
    out = {f"resources/{MARKER_FILE}": b"fixed\n" if wrapper is not None else b"stock\n"}
    out.update({f"binaries/{plat}/{ident}.dll": None for plat in DROPPED_PLATFORMS})
    if wrapper is not None:
        out[f"binaries/{_platform_dir()}/{ident}.so"] = Path(wrapper).read_bytes()
    return out
