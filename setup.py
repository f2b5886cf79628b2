"""The one part of the build pyproject.toml cannot say without setuptools' experimental table: the C
extension that steps a cooperative platoon's followers (d4sumo.model.cooperative). Built without
floating-point contraction or fast math, so each operation rounds as the Python's does; optional, so an
install without a C compiler goes on and the Python plays those platoons."""

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

#: each compiler's way of saying it: no fused multiply-add, no reassociation
EXACT = {"msvc": ["/fp:precise"], "unix": ["-ffp-contract=off", "-fno-fast-math"]}


class ExactBuild(build_ext):
    def build_extensions(self):
        for extension in self.extensions:
            extension.extra_compile_args = EXACT.get(self.compiler.compiler_type, EXACT["unix"])
        super().build_extensions()


setup(ext_modules=[Extension("d4sumo.model._cooperative", ["d4sumo/model/_cooperative.c"], optional=True)],
      cmdclass={"build_ext": ExactBuild})
