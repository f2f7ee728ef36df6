"""Package discovery for the one layout pyproject.toml cannot state alone.

The repository root *is* the ``mdaug`` package (``package-dir = {"mdaug" = "."}`` in
pyproject.toml), so setuptools' ``find`` would name its folders as top-level packages
(``generator``, ``inference``...). Here every folder that is a package under the root
(``find_packages``, tests excluded) is prefixed with ``mdaug.``: ``mdaug.generator.chain``
and any future subpackage ship without being listed by hand. Everything else (metadata,
package data, the console script) stays in pyproject.toml.
"""

from setuptools import find_packages, setup

setup(
    packages=["mdaug"]
    + [f"mdaug.{name}" for name in find_packages(".", exclude=["tests", "tests.*", "build", "build.*"])],
)
