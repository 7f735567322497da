"""pythonfmu3's C++ wrapper with millfmu's fixes, compiled for the FMI 3.0 FMUs.

Every pythonfmu3 FMU carries pythonfmu3's prebuilt wrapper (binaries/<platform>/<id>.so),
which maps the FMI 3.0 C functions to the Python slave. What version 0.3.4 does, measured
with fmpy and read in its sources (sources/src/pythonfmu/PySlaveInstance.cpp):

- a Python exception in any call becomes fmi3Fatal ("irreparably corrupted for all
  instances"), and the wrapper releases its references to the slave class, instance and
  log queue, which fmi3FreeInstance releases a second time. An FMU therefore cannot answer
  an illegal call (setting an output, an unknown value reference, a wrong number of values,
  a refused parameter at fmi3ExitInitializationMode) with fmi3Error as FMI 3.0 requires,
  and a failed instantiation releases a pointer that was never set;
- fmi3DoStep never writes eventHandlingNeeded and earlyReturn: a C host reads whatever its
  variables held;
- fmi3GetFloat64 reads nValues items of the list the slave returns without checking its
  length (a host asking for fewer or more values than the references name);
- the logger calls the host's logMessage also when the host passed NULL;
- fmi3EnterInitializationMode drops its startTime: the slave never learns where its time
  starts;
- at process exit its fini function assigns to the static pyState after that object's own
  destructor has run: a double release, after which glibc may abort ("corrupted
  double-linked list"; valgrind: an invalid read in finalizePythonInterpreter);
- every fmi3InstantiateCoSimulation inserts the resources folder into sys.path again and
  leaks the string; fmi3SetFMUState leaks its result; fmi3GetFMUState on a state handle the
  host passes back for reuse leaks the old state.

PATCHES below fix these in its sources (each edit must apply exactly once, so a different
pythonfmu3 version fails loudly instead of building something untested). The library is
compiled with the system's C++ compiler against this Python's headers with the stable ABI
(Py_LIMITED_API, as pythonfmu3 builds it: one library serves Python 3.x) and cached by the
hash of the patched sources. Only x86_64 Linux is built here: the FMI 3.0 FMUs carry no
Windows binary, since pythonfmu3's prebuilt one has the faults above.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

#: The pythonfmu3 version whose sources PATCHES edit.
PYTHONFMU3_VERSION = "0.3.4"
#: FMI 3.0 platform tuple of the binary built here.
PLATFORM = "x86_64-linux"
#: What the build says about it (build-fmu's output, docs/fmu.md).
PLATFORM_NOTE = ("x86_64 Linux only (binaries/x86_64-linux): pythonfmu3's prebuilt Windows wrapper lacks millfmu's "
                 "fixes, and none is built or tested for Windows")

_HANDLER_OLD_START = ("void PySlaveInstance::handle_py_exception(const std::string& what, PyGILState_STATE gilState) "
                      "const\n{")
_HANDLER_OLD_END = "\nPySlaveInstance::~PySlaveInstance()"
_HANDLER_NEW = r'''void PySlaveInstance::handle_py_exception(const std::string& what, PyGILState_STATE gilState) const
{
    // millfmu: a Python exception fails this call with fmi3Error (std::runtime_error, see
    // fmi_functions.cpp); the instance keeps its references and stays usable. The message
    // of an exception named FmiCallError is the whole message; others are prefixed by the call.
    if (PyErr_Occurred() == nullptr) {
        return;
    }
    PyObject *pExcType, *pExcValue, *pExcTraceback;
    PyErr_Fetch(&pExcType, &pExcValue, &pExcTraceback);
    PyErr_NormalizeException(&pExcType, &pExcValue, &pExcTraceback);
    std::string msg = what + ": unknown Python error";
    if (pExcValue != nullptr) {
        bool own = false;
        PyObject* pName = pExcType != nullptr ? PyObject_GetAttrString(pExcType, "__name__") : nullptr;
        if (pName != nullptr) {
            own = PyUnicode_CompareWithASCIIString(pName, "FmiCallError") == 0;
            Py_DECREF(pName);
        }
        PyErr_Clear();
        PyObject* pText = own ? PyObject_Str(pExcValue) : PyObject_Repr(pExcValue);
        PyObject* pBytes = pText != nullptr ? PyUnicode_AsEncodedString(pText, "utf-8", "replace") : nullptr;
        if (pBytes != nullptr) {
            msg = own ? std::string(PyBytes_AsString(pBytes)) : what + ": " + PyBytes_AsString(pBytes);
        }
        Py_XDECREF(pBytes);
        Py_XDECREF(pText);
    }
    PyErr_Clear();
    Py_XDECREF(pExcType);
    Py_XDECREF(pExcValue);
    Py_XDECREF(pExcTraceback);
    if (pMessages_ != nullptr) {
        clearLogBuffer();  // what the slave logged before it raised
    }
    PyGILState_Release(gilState);
    throw std::runtime_error(msg);
}
'''

#: (file relative to pythonfmu-export/src, old text, new text): each old text must occur once.
PATCHES = (
    ("pythonfmu/PySlaveInstance.hpp", "    PyObject* pClass_;\n", "    PyObject* pClass_{};\n"),
    ("pythonfmu/PySlaveInstance.cpp",
     "        int success = PyList_Insert(sys_path, 0, PyUnicode_FromString(resources_.c_str()));\n",
     "        // millfmu: once per resources folder, without leaking the string.\n"
     "        PyObject* pResources = PyUnicode_FromString(resources_.c_str());\n"
     "        int success = pResources == nullptr ? -1\n"
     "            : (PySequence_Contains(sys_path, pResources) == 1 ? 0 : PyList_Insert(sys_path, 0, pResources));\n"
     "        Py_XDECREF(pResources);\n"),
    ("pythonfmu/PySlaveInstance.cpp",
     "    cppfmu::FMIStatus fmuStatus = cppfmu::FMIOK;\n",
     "    cppfmu::FMIStatus fmuStatus = cppfmu::FMIOK;\n"
     "    // millfmu: the output arguments are always written (no events, no early return).\n"
     "    if (eventHandlingNeeded != nullptr) *eventHandlingNeeded = false;\n"
     "    if (terminateSimulation != nullptr) *terminateSimulation = false;\n"
     "    if (earlyReturn != nullptr) *earlyReturn = false;\n"),
    ("pythonfmu/PySlaveInstance.cpp",
     '            handle_py_exception("[getFloat64] PyObject_CallMethod", gilState);\n        }\n',
     '            handle_py_exception("[getFloat64] PyObject_CallMethod", gilState);\n        }\n'
     "        // millfmu: as many values as the host asked for, else fmi3Error.\n"
     "        if (!PyList_Check(refs) || PyList_Size(refs) != static_cast<Py_ssize_t>(nValues)) {\n"
     "            const auto got = PyList_Check(refs) ? static_cast<long long>(PyList_Size(refs)) : -1LL;\n"
     "            Py_DECREF(refs);\n"
     "            clearLogBuffer();\n"
     "            PyGILState_Release(gilState);\n"
     '            throw std::runtime_error("fmi3GetFloat64: nValues = " + std::to_string(nValues) +\n'
     '                ", but the value references name " + std::to_string(got) + " values");\n'
     "        }\n"),
    ("pythonfmu/PySlaveInstance.cpp",
     "        state = reinterpret_cast<fmi3FMUState*>(f);\n        clearLogBuffer();\n",
     "        // millfmu: a state handle passed back for reuse is replaced: release the old one.\n"
     "        Py_XDECREF(reinterpret_cast<PyObject*>(state));\n"
     "        state = reinterpret_cast<fmi3FMUState*>(f);\n        clearLogBuffer();\n"),
    ("pythonfmu/PySlaveInstance.cpp",
     '            handle_py_exception("[_set_fmu_state] PyObject_CallMethod", gilState);\n        }\n        '
     'clearLogBuffer();\n',
     '            handle_py_exception("[_set_fmu_state] PyObject_CallMethod", gilState);\n        }\n        '
     'Py_DECREF(f);\n        clearLogBuffer();\n'),
    ("cppfmu/cppfmu_common.hpp",
     "        if (m_settings->loggedCategories.empty() ||\n            detail::CanFind(m_settings->loggedCategories, "
     "category)) {\n",
     "        // millfmu: a host may pass no logMessage callback.\n"
     "        if (m_fmiLogger != nullptr && (m_settings->loggedCategories.empty() ||\n"
     "            detail::CanFind(m_settings->loggedCategories, category))) {\n"),
    # fmi3EnterInitializationMode's startTime reaches the slave (setup_experiment): the FMU's
    # time starts there, and fmi3DoStep refuses a currentCommunicationPoint that is not it.
    ("cppfmu/fmi_functions.cpp",
     "fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean, fmi3Float64, fmi3Float64, fmi3Boolean, "
     "fmi3Float64)\n{\n    const auto component = reinterpret_cast<Component*>(c);\n    try {\n"
     "        component->slave->EnterInitializationMode();\n",
     "fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,\n"
     "    fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)\n"
     "{\n    const auto component = reinterpret_cast<Component*>(c);\n    try {\n"
     "        // millfmu: the start time reaches the slave.\n"
     "        component->slave->SetupExperiment(toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);\n"
     "        component->slave->EnterInitializationMode();\n"),
    # At process exit the static pyState's own C++ destructor (an exit handler) runs before
    # the library's fini function, which then assigned to the destroyed shared_ptr: its
    # control block was released a second time and glibc aborted later ("corrupted
    # double-linked list"). The static destructor alone releases it, at exit and at an
    # unloading dlclose alike (as in the FMI 2.0 wrapper, fmu_build.wrapper fix 5).
    ("pythonfmu/PySlaveInstance.cpp",
     "    __attribute__((destructor)) void onLibraryUnload()\n    {\n        finalizePythonInterpreter();\n}\n",
     "    __attribute__((destructor)) void onLibraryUnload()\n    {\n"
     "        // millfmu: nothing; pyState's static destructor has released it by now.\n}\n"),
)

#: Compiled sources, relative to pythonfmu-export/src.
COMPILED = ("cppfmu/cppfmu_cs.cpp", "cppfmu/fmi_functions.cpp", "pythonfmu/PySlaveInstance.cpp")


class WrapperError(RuntimeError):
    """The patched wrapper cannot be built here (names what is missing)."""


def _export_dir() -> Path:
    import pythonfmu3

    if pythonfmu3.__version__ != PYTHONFMU3_VERSION:
        raise WrapperError(f"pythonfmu3 {pythonfmu3.__version__} is installed; millfmu's wrapper fixes are made for "
                           f"{PYTHONFMU3_VERSION} (pip install 'pythonfmu3=={PYTHONFMU3_VERSION}')")
    return Path(pythonfmu3.__file__).resolve().parent / "pythonfmu-export"


def patched_sources() -> dict:
    """{path relative to pythonfmu-export: text} of every wrapper source, PATCHES applied."""
    root = _export_dir()
    texts = {}
    for f in sorted(root.rglob("*")):
        if f.is_file() and f.suffix in (".cpp", ".hpp", ".h", ".txt") and "build" not in f.relative_to(root).parts:
            texts[f.relative_to(root).as_posix()] = f.read_text()
    for rel, old, new in PATCHES:
        key = f"src/{rel}"
        n = texts[key].count(old)
        if n != 1:
            raise WrapperError(f"pythonfmu3 wrapper source {key}: the text to patch occurs {n} times, expected "
                               f"once:\n{old}")
        texts[key] = texts[key].replace(old, new)
    key = "src/pythonfmu/PySlaveInstance.cpp"
    text = texts[key]
    a, b = text.find(_HANDLER_OLD_START), text.find(_HANDLER_OLD_END)
    if a < 0 or b < a or text.count(_HANDLER_OLD_START) != 1:
        raise WrapperError(f"pythonfmu3 wrapper source {key}: handle_py_exception not found as expected")
    texts[key] = text[:a] + _HANDLER_NEW + text[b:]
    return texts


def _cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "millfmu" / "fmi3-wrapper"


def _compiler() -> str:
    if os.environ.get("CXX"):
        cxx = shutil.which(os.environ["CXX"])
        if not cxx:
            raise WrapperError(f"CXX = {os.environ['CXX']!r}: not an executable C++ compiler (needed to compile "
                               "pythonfmu3's wrapper)")
        return cxx
    cxx = shutil.which("g++") or shutil.which("c++") or shutil.which("clang++")
    if not cxx:
        raise WrapperError("building an FMI 3.0 FMU compiles pythonfmu3's wrapper with millfmu's fixes: no C++17 "
                           "compiler found (install g++, Debian: apt-get install g++, or set CXX)")
    return cxx


def wrapper_library(log=None) -> Path:
    """The compiled wrapper (built once, then taken from the cache): a shared library path."""
    if sys.platform != "linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise WrapperError(f"FMI 3.0 FMUs are built for {PLATFORM} only; this machine is {sys.platform} "
                           f"{platform.machine()}")
    texts = patched_sources()
    h = hashlib.sha256()
    for rel, text in sorted(texts.items()):
        h.update(rel.encode() + b"\0" + text.encode() + b"\0")
    lib = _cache_root() / h.hexdigest()[:16] / "libpythonfmu-export.so"
    if lib.is_file():
        return lib
    include = Path(sysconfig.get_paths()["include"])
    if not (include / "Python.h").is_file():
        raise WrapperError(f"building an FMI 3.0 FMU compiles pythonfmu3's wrapper: Python.h is not in {include} "
                           "(install this Python's development headers, Debian: apt-get install python3-dev)")
    cxx = _compiler()
    lib.parent.mkdir(parents=True, exist_ok=True)
    from .leftovers import temp_dir

    with temp_dir("fmi3_wrapper_", dir=lib.parent) as tmp:
        src = Path(tmp) / "pythonfmu-export"
        for rel, text in texts.items():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            (src / rel).write_text(text)
        part = Path(tmp) / lib.name
        cmd = [cxx, "-std=c++17", "-O2", "-fPIC", "-shared", "-s", "-DPy_LIMITED_API", f"-I{include}",
               f"-I{src / 'src'}",
               *[str(src / "src" / u) for u in COMPILED], "-o", str(part)]
        if log:
            log(f"compiling pythonfmu3's wrapper with millfmu's fixes ({Path(cxx).name}, once; cached in {lib.parent})")
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            raise WrapperError("compiling pythonfmu3's wrapper failed:\n" + " ".join(cmd) + "\n" + r.stderr[-4000:])
        part.replace(lib)  # atomic: a concurrent build writes the same file
    return lib


def fmu_replacements(model_identifier: str, log=None) -> dict:
    """What an FMI 3.0 FMU built by pythonfmu3 gets instead of pythonfmu3's wrapper: {name in
    the FMU: bytes, or None to drop the entry} for the binaries and the sources."""
    lib = wrapper_library(log)
    out = {f"binaries/{PLATFORM}/{model_identifier}.so": lib.read_bytes(),
           f"binaries/x86_64-windows/{model_identifier}.dll": None}
    for rel, text in patched_sources().items():
        out[f"sources/{rel}"] = text.encode()
    return out
