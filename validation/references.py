"""The reference-code loaders, from the package (the CLI's comparisons use them too)."""
from lockgraph.reference_codes import (MissingReference, lammps_module, liggghts_binary,  # noqa: F401
                                       liggghts_version, rebound)
