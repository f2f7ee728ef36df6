"""Package discovery for the one layout pyproject.toml cannot state alone.

The repository root *is* the ``mdaug`` package (``package-dir = {"mdaug" = "."}`` in
pyproject.toml), so setuptools' ``find`` would name its folders as top-level packages
(``generator``, ``inference``...). Here every folder that is a package under the root
(``find_packages``, tests excluded) is prefixed with ``mdaug.``: ``mdaug.generator.chain``
and any future subpackage ship without being listed by hand. Everything else (metadata,
package data, the console script) stays in pyproject.toml.
"""

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

BUILD_FILES = {"setup"}
"""Modules of the root folder that build the package and are not part of it: ``setup.py``
lies in the root, which *is* ``mdaug``, so setuptools would install it as ``mdaug/setup.py``."""


class BuildPy(build_py):
    """build_py that leaves the build's own files (:data:`BUILD_FILES`) out of ``mdaug``."""

    def find_package_modules(self, package, package_dir):
        modules = super().find_package_modules(package, package_dir)
        return [m for m in modules if not (package == "mdaug" and m[1] in BUILD_FILES)]


setup(
    packages=["mdaug"]
    + [f"mdaug.{name}" for name in find_packages(".", exclude=["tests", "tests.*", "build", "build.*"])],
    cmdclass={"build_py": BuildPy},
)
