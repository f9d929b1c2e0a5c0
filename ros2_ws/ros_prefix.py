#!/usr/bin/env python3
"""The optional ROS 2 Jazzy prefix: rclpy 7.1.6 on Fast DDS from PyPI wheels, and moose_msgs built for it.

Usage (``make ros``)::

    python3 ros2_ws/ros_prefix.py [PREFIX]      # PREFIX: $MOOSE_ROS_PREFIX, else .venv-ros
    . .venv-ros/setup.sh                        # then rclpy, moose_msgs and `moose` in this shell

Steps, each skipped when its inputs have not changed:

1. **Prefix.** A virtual environment of its own with the pinned wheels of ``requirements-jazzy.txt``
   and the project, editable as in ``.venv`` (one pip resolve, so ROS and project share one numpy).
   Recreated from scratch when the requirements, ``pyproject.toml``, moose_ros's ``setup.py`` or the
   interpreter change. It is a full ament prefix (``share/ament_index``, ``share/<pkg>/cmake``).
2. **Patch.** The wheels were built in a manylinux image: their exported ``*__rosidl_generator_py``
   CMake targets name that image's Python and NumPy include folders. They are replaced by the local
   interpreter's and NumPy's (every run, idempotent); then every include folder that an exported
   target names must exist, or the run stops and names them.
3. **Messages.** ``ros2_ws/upstream/tf2_msgs`` (Jazzy's ``TFMessage``, which no wheel carries),
   then ``ros2_ws/src/moose_msgs`` (the ``.msg`` files are the single source), are built with CMake,
   the rosidl generators and ament_cmake of the same wheels (C, C++ and Python type support) into
   ``PREFIX/install``, and every message class is checked through rclpy (type support loads, a
   default message serialises and deserialises). Rebuilt from scratch when the package files, the
   installed wheel set, the toolchain or this script change (the key is stored in
   ``PREFIX/install/.build-key``, written last, so an interrupted build is redone).
4. **Environment.** ``PREFIX/ros-env.json`` (read by :func:`environment`) and ``PREFIX/setup.sh``
   (the same values for a shell): ``AMENT_PREFIX_PATH``, ``CMAKE_PREFIX_PATH``, ``LD_LIBRARY_PATH``,
   ``PYTHONPATH``, ``PATH``, ``ROS_DISTRO`` and ``RMW_IMPLEMENTATION=rmw_fastrtps_cpp`` (the only
   RMW in the prefix). It also sets ``_ROS_WHEELS_BOOTSTRAP_COMPLETE=1``: the wheels install a
   ``.pth`` hook (ros_wheels_bootstrapper) that otherwise re-executes every interpreter of the
   prefix with ``LD_LIBRARY_PATH`` rebuilt from a set, in no fixed order.

Only the standard library is used here; the prefix's own interpreter answers questions about it.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterable, Mapping, Optional

REPO = Path(__file__).resolve().parents[1]
REQUIREMENTS = REPO / "ros2_ws" / "requirements-jazzy.txt"
MSGS = REPO / "ros2_ws" / "src" / "moose_msgs"
PACKAGES = (REPO / "ros2_ws" / "upstream" / "tf2_msgs", MSGS)
"""The message packages built into the prefix, in build order."""
PROJECT_FILES = (REPO / "pyproject.toml", REPO / "ros2_ws" / "src" / "moose_ros" / "setup.py")
DISTRO = "jazzy"
RMW = "rmw_fastrtps_cpp"
ENV_FILE = "ros-env.json"
SETUP_FILE = "setup.sh"
INSTALL_KEY_FILE = ".moose-install-key"
BUILD_KEY_FILE = ".build-key"
BOOTSTRAP_GUARD = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"

_MANYLINUX_PYTHON = re.compile(r"/opt/python/cp3\d+-cp3\d+t?/include/python3\.\d+t?")
_MANYLINUX_NUMPY = re.compile(
    r"/opt/python/cp3\d+-cp3\d+t?/lib/python3\.\d+t?/site-packages/numpy/(?:_core|core)/include")
_INCLUDE_DIRS = re.compile(r'INTERFACE_INCLUDE_DIRECTORIES\s+"([^"]*)"')

_INFO = """
import json, sys, sysconfig
from importlib.metadata import distributions
import numpy
print(json.dumps({
    "version": "%d.%d" % sys.version_info[:2],
    "include": sysconfig.get_paths()["include"],
    "numpy_include": numpy.get_include(),
    "site": sysconfig.get_paths()["purelib"],
    "dists": sorted({"%s==%s" % (d.metadata["Name"].lower(), d.version) for d in distributions()}),
}))
"""

_CHECK = """
import sys
import rclpy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.type_support import check_is_valid_msg_type
from importlib import import_module
for name in sys.argv[1:]:
    package, _, kind = name.split("/")
    cls = getattr(import_module(package + ".msg"), kind)
    check_is_valid_msg_type(cls)
    if deserialize_message(serialize_message(cls()), cls) != cls():
        sys.exit("%s does not survive serialisation" % name)
print("%d messages" % (len(sys.argv) - 1))
"""


class PrefixError(RuntimeError):
    """A step failed; the message says which and what to do."""


def default_prefix() -> Path:
    """``$MOOSE_ROS_PREFIX`` if set, else ``.venv-ros`` in the repository."""
    return Path(os.environ.get("MOOSE_ROS_PREFIX") or REPO / ".venv-ros").absolute()


def apply(values: Mapping, base: Mapping[str, str]) -> dict[str, str]:
    """``base`` with the variables of an environment spec (:func:`spec`) set and prepended."""
    env = dict(base)
    env.update(values["set"])
    for name, parts in values["prepend"].items():
        env[name] = os.pathsep.join(parts + ([env[name]] if env.get(name) else []))
    return env


def environment(prefix: Optional[Path] = None, base: Optional[Mapping[str, str]] = None) -> dict[str, str]:
    """The environment of a process that uses the prefix: ``base`` (default ``os.environ``) with the
    variables of ``PREFIX/ros-env.json`` set and prepended.  Start such a process with the prefix's
    interpreter, ``environment()["MOOSE_ROS_PYTHON"]``, which has the project installed too.
    Raises :class:`FileNotFoundError` when the prefix has not been made (``make ros``)."""
    prefix = Path(prefix or default_prefix())
    values = json.loads((prefix / ENV_FILE).read_text(encoding="utf-8"))
    return apply(values, os.environ if base is None else base)


def _digest(parts: Iterable[bytes]) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(hashlib.sha256(part).digest())
    return h.hexdigest()


def _run(cmd: list[str], log: Optional[Path] = None, env: Optional[Mapping[str, str]] = None) -> str:
    """Run a command; its output goes to ``log`` (if given) and is returned.  Raises PrefixError
    with the last lines of the output on a non-zero exit."""
    result = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=None if env is None else dict(env))
    if log is not None:
        log.parent.mkdir(parents=True, exist_ok=True)
        with open(log, "a", encoding="utf-8") as f:
            f.write(f"$ {' '.join(cmd)}\n{result.stdout}\n")
    if result.returncode != 0:
        tail = "\n".join(result.stdout.strip().splitlines()[-25:])
        where = f" (full output: {log})" if log is not None else ""
        raise PrefixError(f"`{' '.join(cmd)}` failed with exit status {result.returncode}{where}:\n{tail}")
    return result.stdout


def _first_line(cmd: list[str]) -> str:
    return _run(cmd).splitlines()[0].strip()


def _quiet_env(extra: Optional[Mapping[str, str]] = None) -> dict[str, str]:
    """os.environ with the wheels' re-exec hook disabled and a ROS environment of a shell left out."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH")}
    env[BOOTSTRAP_GUARD] = "1"
    env.update(extra or {})
    return env


def base_python() -> str:
    """The interpreter that creates the prefix: this one, or the one it was made from when it runs
    in a virtual environment (possibly the prefix itself, which step 1 may delete)."""
    return os.path.realpath(getattr(sys, "_base_executable", sys.executable))


def install_key() -> str:
    """What the prefix's Python packages depend on: the requirements, the project's package
    definitions, the checkout (the project is installed editable from it) and the interpreter
    that creates the environment."""
    files = [REQUIREMENTS, *PROJECT_FILES]
    return _digest([f.read_bytes() for f in files] + [str(REPO).encode(), sys.version.encode(), base_python().encode()])


def ensure_installed(prefix: Path, log: Path) -> bool:
    """Step 1: the virtual environment with ROS and the project.  Returns False when it was current."""
    key = install_key()
    stamp = prefix / INSTALL_KEY_FILE
    if stamp.is_file() and stamp.read_text(encoding="utf-8").strip() == key:
        return False
    if prefix.exists():
        if not (prefix / "pyvenv.cfg").is_file() and any(prefix.iterdir()):
            raise PrefixError(f"{prefix} exists and is not a virtual environment; choose another "
                              "prefix (MOOSE_ROS_PREFIX) or remove it")
        shutil.rmtree(prefix)
    _run([base_python(), "-m", "venv", str(prefix)], log)
    python = str(prefix / "bin" / "python")
    _run([python, "-m", "pip", "install", "--quiet", "-r", str(REQUIREMENTS),
          "-e", f"{REPO}[test]", "-e", str(REPO / "ros2_ws" / "src" / "moose_ros")], log, _quiet_env())
    stamp.write_text(key + "\n", encoding="utf-8")
    return True


def query(prefix: Path) -> dict:
    """The prefix interpreter's include folders, site-packages and installed distributions."""
    return json.loads(_run([str(prefix / "bin" / "python"), "-c", _INFO], env=_quiet_env()))


def patch_exports(prefix: Path, info: dict) -> int:
    """Step 2: point the manylinux include folders of the exported CMake targets at the local ones.
    Returns how many files were changed; raises PrefixError naming include folders that do not exist."""
    changed = 0
    files = sorted((prefix / "share").glob("*/cmake/*.cmake"))
    for path in files:
        text = path.read_text(encoding="utf-8")
        new = _MANYLINUX_NUMPY.sub(info["numpy_include"], _MANYLINUX_PYTHON.sub(info["include"], text))
        if new != text:
            path.write_text(new, encoding="utf-8")
            changed += 1
    missing = []
    for path in files:
        for value in _INCLUDE_DIRS.findall(path.read_text(encoding="utf-8")):
            for folder in value.split(";"):
                if folder.startswith("/") and "$" not in folder and not Path(folder).is_dir():
                    missing.append(f"{path.relative_to(prefix)}: {folder}")
    if missing:
        raise PrefixError("exported CMake targets name include folders that do not exist:\n  "
                          + "\n  ".join(missing))
    return changed


def msg_names() -> list[str]:
    """The message types built here (``pkg/msg/Name``), from the packages' .msg files."""
    return [f"{pkg.name}/msg/{p.stem}" for pkg in PACKAGES for p in sorted((pkg / "msg").glob("*.msg"))]


def build_key(info: dict) -> str:
    """What the message build depends on: the packages' files, the installed wheel set (NumPy
    included), the toolchain and this script."""
    sources = sorted(p for pkg in PACKAGES for p in pkg.rglob("*") if p.is_file())
    parts = [str(p.relative_to(REPO)).encode() + b"\0" + p.read_bytes() for p in sources]
    parts += [Path(__file__).read_bytes(), json.dumps(info["dists"]).encode(), info["version"].encode(),
              _first_line(["cmake", "--version"]).encode(), _first_line(["c++", "--version"]).encode(),
              _first_line(["cc", "--version"]).encode()]
    return _digest(parts)


def spec(prefix: Path, info: dict) -> dict:
    """The environment of the prefix (step 4), as written to ros-env.json."""
    install = prefix / "install"
    libs = sorted(str(p) for p in Path(info["site"]).glob("ros_*.libs") if p.is_dir())
    return {
        "distro": DISTRO,
        "python_version": info["version"],
        "set": {
            "ROS_DISTRO": DISTRO, "ROS_VERSION": "2", "ROS_PYTHON_VERSION": "3",
            "RMW_IMPLEMENTATION": RMW, BOOTSTRAP_GUARD: "1",
            "MOOSE_ROS_PREFIX": str(prefix), "MOOSE_ROS_PYTHON": str(prefix / "bin" / "python"),
        },
        "prepend": {
            "PATH": [str(prefix / "bin")],
            "AMENT_PREFIX_PATH": [str(install), str(prefix)],
            "CMAKE_PREFIX_PATH": [str(install), str(prefix)],
            "LD_LIBRARY_PATH": [str(install / "lib"), str(prefix / "lib"), *libs],
            "PYTHONPATH": [str(install / "lib" / f"python{info['version']}" / "site-packages")],
        },
    }


def build_msgs(prefix: Path, info: dict, values: dict, jobs: int, log: Path) -> bool:
    """Step 3: generate and build the message packages into PREFIX/install.  Returns False when it was current."""
    key = build_key(info)
    install = prefix / "install"
    stamp = install / BUILD_KEY_FILE
    if stamp.is_file() and stamp.read_text(encoding="utf-8").strip() == key:
        return False
    for folder in (prefix / "build" / "msgs", install):
        if folder.exists():
            shutil.rmtree(folder)
    search = os.pathsep.join([str(install), str(prefix)])  # a package finds the ones built before it
    env = _quiet_env({"AMENT_PREFIX_PATH": search,
                      "PATH": os.pathsep.join([str(prefix / "bin"), os.environ.get("PATH", "")])})
    for package in PACKAGES:
        build = prefix / "build" / "msgs" / package.name
        _run(["cmake", "-S", str(package), "-B", str(build), f"-DCMAKE_PREFIX_PATH={install};{prefix}",
              f"-DPython3_EXECUTABLE={prefix / 'bin' / 'python'}", "-DBUILD_TESTING=OFF",
              "-DCMAKE_BUILD_TYPE=Release", f"-DCMAKE_INSTALL_PREFIX={install}"], log, env)
        _run(["cmake", "--build", str(build), "-j", str(jobs)], log, env)
        _run(["cmake", "--install", str(build)], log, env)
    names = msg_names()
    out = _run([str(prefix / "bin" / "python"), "-c", _CHECK, *names], log, apply(values, _quiet_env()))
    if out.strip() != f"{len(names)} messages":
        raise PrefixError(f"message check printed {out.strip()!r}, expected '{len(names)} messages'")
    stamp.write_text(key + "\n", encoding="utf-8")
    return True


def write_env(prefix: Path, values: dict) -> None:
    """Step 4: PREFIX/ros-env.json and PREFIX/setup.sh, from the same values."""
    (prefix / ENV_FILE).write_text(json.dumps(values, indent=2) + "\n", encoding="utf-8")
    lines = [f"# ROS 2 {DISTRO.capitalize()} from wheels with moose_msgs; written by ros2_ws/ros_prefix.py "
             "(make ros).", f"# Use: . {prefix}/{SETUP_FILE}"]
    for value in [*values["set"].values(), *(v for parts in values["prepend"].values() for v in parts)]:
        if "'" in value or "\n" in value:
            raise PrefixError(f"cannot write {value!r} into {SETUP_FILE}: it contains a quote or a newline")
    lines += [f"export {name}='{value}'" for name, value in values["set"].items()]
    for name, parts in values["prepend"].items():
        joined = os.pathsep.join(parts)
        lines.append(f"export {name}='{joined}'\"${{{name}:+:${name}}}\"")
    (prefix / SETUP_FILE).write_text("\n".join(lines) + "\n", encoding="utf-8")


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="ros_prefix", description=__doc__.split("\n\n")[0])
    parser.add_argument("prefix", nargs="?", type=Path, help="default: $MOOSE_ROS_PREFIX, else .venv-ros")
    parser.add_argument("--jobs", "-j", type=int, default=os.cpu_count() or 1, help="parallel build jobs")
    args = parser.parse_args(argv)
    prefix = (args.prefix or default_prefix()).absolute()
    log = prefix / "build" / "ros_prefix.log"
    try:
        for tool in ("cmake", "cc", "c++"):
            if shutil.which(tool) is None:
                raise PrefixError(f"`{tool}` is not on PATH: building moose_msgs needs CMake and a C/C++ compiler")
        if args.jobs < 1:
            raise PrefixError(f"--jobs = {args.jobs}: expected an integer >= 1")
        log.unlink(missing_ok=True)
        t0 = time.monotonic()
        installed = ensure_installed(prefix, log)
        t1 = time.monotonic()
        info = query(prefix)
        patched = patch_exports(prefix, info)
        values = spec(prefix, info)
        built = build_msgs(prefix, info, values, args.jobs, log)
        t2 = time.monotonic()
        write_env(prefix, values)
    except PrefixError as err:
        print(f"ros_prefix: error: {err}", file=sys.stderr)
        return 1
    print(f"ros_prefix: wheels {'installed' if installed else 'current'} ({t1 - t0:.1f} s), "
          f"{patched} CMake export files patched, tf2_msgs and moose_msgs {'built' if built else 'current'} "
          f"({t2 - t1:.1f} s) for Python {info['version']}")
    print(f"ros_prefix: environment: . {prefix / SETUP_FILE}   (or {prefix / ENV_FILE})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
