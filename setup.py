"""The one part of the build pyproject.toml cannot say without setuptools' experimental table: the C
extension that steps a platoon's followers (d4sumo.model.controllers.compiled), its switching law the one the FMUs
d4sumo ships run (d4sumo/fmus/switching.h), and the C++ one that calls libsumo's own functions for its step loop
(d4sumo/engine/_sumo_calls.cpp). Built without
floating-point contraction or fast math, so each operation rounds as the Python's does; optional, so an
install without a C (or C++) compiler goes on and the Python plays those platoons (calls libsumo as it does)."""

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

#: each compiler's way of saying it: no fused multiply-add, no reassociation
EXACT = {"msvc": ["/fp:precise"], "unix": ["-ffp-contract=off", "-fno-fast-math"]}


class ExactBuild(build_ext):
    def build_extensions(self):
        for extension in self.extensions:
            extension.extra_compile_args = EXACT.get(self.compiler.compiler_type, EXACT["unix"])
        super().build_extensions()


PARTS = ["d4sumo/model/controllers/csrc/world_calls.h", "d4sumo/model/controllers/csrc/followers.h",
         "d4sumo/model/controllers/csrc/convert.h", "d4sumo/model/controllers/csrc/laws.h",
         "d4sumo/model/controllers/csrc/as_run.h",
         "d4sumo/model/controllers/csrc/channel.h", "d4sumo/model/controllers/csrc/making.h",
         "d4sumo/model/controllers/csrc/column.h", "d4sumo/fmus/switching.h"]

setup(ext_modules=[Extension("d4sumo.model.controllers._followers", ["d4sumo/model/controllers/_followers.c"], depends=PARTS,
                             include_dirs=["d4sumo/model/controllers/csrc", "d4sumo/fmus"], optional=True),
                   # libsumo's C++ functions for the step loop in C (d4sumo/engine/_sumo_calls.cpp): optional, as the other
                   Extension("d4sumo.engine._sumo_calls", ["d4sumo/engine/_sumo_calls.cpp"],
                             depends=["d4sumo/model/controllers/csrc/world_calls.h", "d4sumo/engine/traffic_sense.h",
                                      "d4sumo/engine/lateral_sense.h"],
                             include_dirs=["d4sumo/model/controllers/csrc"], libraries=["dl"], language="c++", optional=True)],
      cmdclass={"build_ext": ExactBuild})
