"""Each kernel of the 3D path compiles once: no second specialization of a kernel for a
caller's constant argument (numba types a literal argument, or a variable that holds a
constant on its first pass through a loop, as ``Literal[int]`` and compiles a specialization
for it) or for an index of another integer width.

The signatures come from a child process (dispatchers of its own, the usual cache): a small
3D workload (a tetrahedralisation, moved so that flips and relocations run, points inserted
and removed, Sibson coordinates inside and on the hull, by Watson's decomposition and by
Box 1) calls the entry kernels. A kernel loaded from the cache does not type its callees, so
every kernel that has a signature is typed again (type inference only, nothing lowered),
which asks its callees for theirs, until no new signature appears: the signatures a
compilation from scratch makes. (The parallel loops' own typing, where a ``prange`` index is
unsigned, is not repeated.)

Run as a script, this file is that child and prints the signatures as JSON.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import pytest

ROOT = Path(__file__).resolve().parents[1]

#: kernels that callers used to compile two or three times (a literal, an int32 against an
#: int64 index, an int32 against an int64 array)
ONCE = [
    "coordinates.lasserre_cell.lasserre_cell", "coordinates.lasserre_cell.vertex_simplices",
    "coordinates.watson3d._pair", "coordinates.watson3d.walk",
    "geometry.delaunay3d_build.insert_all", "geometry.delaunay3d_build.insert_point",
    "geometry.delaunay3d_build.cavity", "geometry.delaunay3d_build.locate",
    "geometry.delaunay3d_build._perturbed_inside", "geometry.delaunay3d_build._retriangulate",
    "geometry.delaunay3d_flips.face_fails", "geometry.delaunay3d_flips.glue",
    "geometry.delaunay3d_flips.internal", "geometry.delaunay3d_flips.push",
    "geometry.delaunay3d_repair._mark", "geometry.simplices_nd.hull_distance",
    "geometry.predicates3d._minor4", "geometry.predicates3d._copy",
    "geometry.expansions.expansion_sum", "geometry.expansions.approximate",
]
#: literals passed on purpose: the exponent bounds of the exact predicates' lattice shortcut
#: (tiny kernels, one specialization per predicate)
LITERAL_OK = {"geometry.predicates._on_lattice", "geometry.predicates3d._on_lattice",
              "geometry.expansions.rescale_exponent"}


def workload():
    import numpy as np

    from skfem_nem.coordinates import sibson_coordinates_nd
    from skfem_nem.geometry.delaunay3d import Delaunay3D
    from skfem_nem.geometry.nodesets3d import box_nodes_3d

    p = box_nodes_3d(300, seed=1)
    x, y, z = np.pi * p.T
    flow = np.c_[np.sin(x) * np.cos(y), -np.cos(x) * np.sin(y), 0.0 * z]
    tri, report = Delaunay3D(p).moved(p + 0.05 * flow)
    assert report["flips"] > 0 and report["relocated"] > 0
    tri = tri.inserted(0.1 + 0.8 * np.random.default_rng(1).random((5, 3))).removed([7, 8])
    q = 0.05 + 0.9 * np.random.default_rng(0).random((1200, 3))
    q[:20, 2] = 0.0                                   # on the hull
    sibson_coordinates_nd(tri.points, q, delaunay=tri)
    sibson_coordinates_nd(tri.points, q[20:60], gradient=True, delaunay=tri)


def typing_only():
    """A function typing a kernel for a signature (numba's untyped passes and its type
    inference, no lowering): the calls it makes ask the callees for their signatures."""
    from numba.core import compiler
    from numba.core.compiler_machinery import FunctionPass, PassManager, register_pass
    from numba.core.typed_passes import NopythonTypeInference

    @register_pass(mutates_CFG=False, analysis_only=True)
    class StopAfterTyping(FunctionPass):
        _name = "stop_after_typing"

        def __init__(self):
            FunctionPass.__init__(self)

        def run_pass(self, state):
            state.cr = True  # a result: the compilation ends here
            return False

    class Typing(compiler.CompilerBase):
        def define_pipelines(self):
            pm = PassManager("typing only")
            pm.passes.extend(compiler.DefaultPassBuilder.define_untyped_pipeline(
                self.state).passes)
            pm.add_pass(NopythonTypeInference, "type inference")
            pm.add_pass(StopAfterTyping, "stop after typing")
            pm.finalize()
            return [pm]

    def typed(disp, sig):
        flags = compiler.Flags()
        disp.targetdescr.options.parse_as_flags(flags, disp.targetoptions)
        compiler.compile_extra(disp.targetdescr.typing_context, disp.targetdescr.target_context,
                               disp.py_func, sig, None, flags, disp.locals,
                               pipeline_class=Typing)
    return typed


def kernels():
    from numba.core.dispatcher import Dispatcher
    found = {}
    for name, mod in list(sys.modules.items()):
        if name.startswith("skfem_nem.") and mod is not None:
            for v in list(vars(mod).values()):
                if isinstance(v, Dispatcher) and v.py_func.__module__ == name:
                    found[id(v)] = v
    return list(found.values())


def has_literal(t):
    from numba.core import types
    return isinstance(t, types.Literal) or (
        isinstance(t, types.BaseTuple) and any(has_literal(u) for u in t.types))


def signatures():
    """``{kernel: [[argument type, has a literal], ...] per signature}`` after the workload
    and the typing of every kernel reached."""
    workload()
    typed = typing_only()
    done = set()
    while True:
        todo = [(k, s) for k in kernels() for s in k.signatures if (id(k), s) not in done]
        if not todo:
            break
        for k, s in todo:
            done.add((id(k), s))
            typed(k, s)
    return {f"{k.py_func.__module__[len('skfem_nem.'):]}.{k.py_func.__qualname__}":
            [[[str(a), has_literal(a)] for a in s] for s in k.signatures] for k in kernels()}


@pytest.fixture(scope="module")
def compiled():
    if numba.config.DISABLE_JIT:
        pytest.skip("numba's JIT is disabled")
    path = os.pathsep.join([str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p])
    run = subprocess.run([sys.executable, __file__], capture_output=True, text=True, cwd=ROOT,
                         env=dict(os.environ, PYTHONPATH=path))
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.splitlines()[-1])


def test_the_workload_reaches_the_kernels(compiled):
    assert not [k for k in ONCE if not compiled.get(k)]


def test_each_kernel_compiles_once(compiled):
    twice = {k: [", ".join(a for a, _ in s) for s in compiled[k]] for k in ONCE
             if len(compiled.get(k, [])) > 1}
    assert not twice, "\n".join(f"{k}:\n  " + "\n  ".join(v) for k, v in twice.items())


def test_no_literal_specializations(compiled):
    literal = {k: [a for s in sigs for a, lit in s if lit] for k, sigs in compiled.items()
               if k not in LITERAL_OK}
    literal = {k: v for k, v in literal.items() if v}
    assert not literal, "\n".join(f"{k}: {', '.join(v)}" for k, v in literal.items())


if __name__ == "__main__":
    print(json.dumps(signatures()))
