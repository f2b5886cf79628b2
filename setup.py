"""The one part of the build pyproject.toml cannot say without setuptools' experimental table: the C
extension that steps a cooperative platoon's followers (d4sumo.model.cooperative). Built without
floating-point contraction, so each operation rounds as the Python's does; optional, so an install without
a C compiler goes on and the Python plays those platoons."""

from setuptools import Extension, setup

setup(ext_modules=[Extension("d4sumo.model._cooperative", ["d4sumo/model/_cooperative.c"],
                             extra_compile_args=["-ffp-contract=off", "-fno-fast-math"], optional=True)])
