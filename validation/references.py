"""The reference-code loaders, from the package (the CLI's comparisons use them too)."""
from lockgraph.reference_codes import (MissingReference, chromium_binary, lammps_binary,
                                       lammps_module, liggghts_binary, liggghts_version, rebound)

__all__ = ["MissingReference", "chromium_binary", "lammps_binary", "lammps_module",
           "liggghts_binary", "liggghts_version", "rebound"]
