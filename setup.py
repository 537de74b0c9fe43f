"""Build hook (the rest of the configuration is in pyproject.toml).

pbr installs ``pbr-libllvm.pth`` next to its package in site-packages. Python runs the
file's one line at start-up (``import _pbr_libllvm``), which points Dr.Jit at a usable
libLLVM (``DRJIT_LIBLLVM_PATH``) before anything imports ``drjit`` or ``mitsuba``, so
Mitsuba scripts that import ``mitsuba`` before ``pbr`` work. See src/_pbr_libllvm.py.
"""

import os

from setuptools import setup
from setuptools.command.build_py import build_py

PTH_NAME = "pbr-libllvm.pth"
PTH_LINE = "import _pbr_libllvm\n"


class build_py_with_pth(build_py):
    """``build_py`` that also writes the start-up ``.pth`` file at the root of the
    installed tree: ``build_lib`` for wheels, the editable wheel's tree for ``pip
    install -e`` (where setuptools sets ``install_lib`` to it and copies nothing from
    ``build_lib``)."""

    def run(self):
        super().run()
        root = self.get_finalized_command("install").install_lib if self.editable_mode else self.build_lib
        os.makedirs(root, exist_ok=True)
        with open(os.path.join(root, PTH_NAME), "w") as f:
            f.write(PTH_LINE)

    def get_outputs(self, include_bytecode=1):
        return list(super().get_outputs(include_bytecode)) + [os.path.join(self.build_lib, PTH_NAME)]


setup(cmdclass={"build_py": build_py_with_pth})
