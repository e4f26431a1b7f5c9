"""volscatter for USD: multiple scattering in participating media for USD stages.

- :mod:`volscatter._native` -- ctypes binding to libvolscatter (Scene, Session, Result, Image, VolscatterError)
- :mod:`volscatter.stage` -- reading a stage (pxr) into volscatter's scene JSON
- :mod:`volscatter.render` -- rendering and baking stages
- :mod:`volscatter.cli` -- the ``volscatter-usd`` command
"""

from ._native import (ABI_VERSION, GRID_FORMAT_EXR, GRID_FORMAT_VDB, Image, Result, Scene, Session, VolscatterError,
                      abi_version, library_path, version)

__version__ = "0.1.0"

__all__ = ["ABI_VERSION", "GRID_FORMAT_EXR", "GRID_FORMAT_VDB", "Image", "Result", "Scene", "Session", "VolscatterError",
           "abi_version", "library_path", "version", "__version__"]
