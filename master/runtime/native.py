"""The compiled stepping kernel (kernel.c) and its ctypes mirror of kernel.h.

`pip install` builds kernel.c into `_kernel*.so` beside this file (setup.py). In a development
checkout a kernel.c or kernel.h newer than the built library is rebuilt here with the system C
compiler, so an edit never runs stale code. `library()` checks that the structure sizes and the
shared constants agree with C.
"""

from __future__ import annotations

import ctypes as C
import importlib.machinery
import os
import shutil
import subprocess
import tempfile
from functools import cache
from pathlib import Path

from master.scenario.model import LOOP_METHODS, TRANSFORMATIONS
from master.schedule import EDGE_ASSUMED
from master.solvers import SOLVERS

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "kernel.c"
HEADER = HERE / "kernel.h"
SCHEDULED = HERE / "scheduled.c"  # included by kernel.c
# a source checkout (pyproject.toml beside the package): rebuilt when stale; an installed package
# uses the library pip built (its kernel.c, shipped for reference, may be unpacked after it)
CHECKOUT = (HERE.parent.parent / "pyproject.toml").is_file()
CFLAGS = ["-O2", "-std=c99", "-fPIC", "-ffp-contract=off", "-Wall", "-Wextra"]
# the fixed-step methods and the LU the project's FMUs use (fmus/solvers), linked into the kernel for
# Model Exchange components and algebraic loops: one implementation (setup.py builds the same)
FMUS = HERE.parent.parent / "fmus"
SOLVER_SOURCES = [FMUS / "solvers" / "solvers.c", FMUS / "solvers" / "lu.c", FMUS / "solvers" / "events.c"]
INCLUDES = [FMUS / "solvers", FMUS / "fmi"]  # solvers.h, and model.h for SolverKind

# mk_run / mk_initial_sweep / mk_record_row codes and failing calls (kernel.h)
(
    DONE,
    ROWS_FULL,
    YIELD,
    FMI_ERROR,
    NOT_FINITE,
    DIVERGED,
    ABORTED,
    STOPPED,
    INEXACT,
    TOO_LONG,
    NOT_CONVERGED,
    EVENT,
    NOT_SETTLED,  # iterated macro steps: the sweeps did not settle (kernel.h)
    CLOCK,  # a Scheduled Execution FMU counted a clock down off its grid (kernel.h)
) = range(14)
NEVER = 2**62  # stop_at while no FMU has ended the simulation
EARLY_RETURNS = 1_000_000  # FMI 3 event mode: most early returns in a communication step (MK_EARLY_RETURNS)
CALLS = (
    "set_real",
    "set_derivatives",
    "do_step",
    "get_real",
    "get_state",
    "set_state",
    "free_state",
    "get_integer",
    "get_boolean",
    "set_integer",
    "set_boolean",
    "get_typed",
    "set_typed",
    "get_string",
    "set_string",
    "get_binary",
    "set_binary",
    # Model Exchange (kernel.h: mk_component.me)
    "set_time",
    "set_states",
    "get_states",
    "get_derivatives",
    "completed_step",
    "directional_derivative",
    "solver",
    # Model Exchange events
    "get_event_indicators",
    "enter_event_mode",
    "update_discrete_states",
    "enter_continuous_time_mode",
    # Scheduled Execution (kernel.h: mk_scheduled)
    "activate_model_partition",
    "get_clock",
    "get_interval",
    # FMI 3 Co-Simulation event mode
    "enter_step_mode",
    "set_clock",
)
REAL_SAMPLE, INTEGER, BOOLEAN = range(3)
KIND_CODES = {"Real": REAL_SAMPLE, "Integer": INTEGER, "Boolean": BOOLEAN}  # schedule.KINDS -> kernel kind
# FMI 3 values set and read through the calls of their own type: kind by type (an Enumeration: Int64)
# and Clock connections: an output clock's count of ticks (kernel.h MK_CLOCK_COUNT)
TYPED = {"Float32": 3, "Int8": 4, "UInt8": 5, "Int16": 6, "UInt16": 7, "UInt32": 8, "Int64": 9, "UInt64": 10,
         "Clock": 11}  # fmt: skip
KINDS = 12
# recorded columns of other kinds (kernel.h mk_record): a link column's latest coupling error, a
# String and a Binary (read at the row into the text ring)
COUPLING_ERROR, RECORD_STRING, RECORD_BINARY = KINDS, KINDS + 1, KINDS + 2
# how a recorded value lies in its row's 8 bytes (kernel.h MK_STORE_*)
STORE = {"float64": 0, "int64": 1, "uint64": 2}
ERROR_FIELDS = 6  # mk_link.error per column: max, sum of squares, count, min, max, latest
LATE_BINS = 10000
TEXT_MAX = 1023  # bytes of a String or Binary a connection carries and a row records
STRING_SLOT = 8 + TEXT_MAX + 1  # a text ring's slot: the length (uint64), the bytes, a zero
CONSTANTS = {
    "MK_KINDS": KINDS,
    "MK_COUPLING_ERROR": COUPLING_ERROR,
    "MK_ERROR_FIELDS": ERROR_FIELDS,
    "MK_STRING_SLOT": STRING_SLOT,
    "MK_TEXT_MAX": TEXT_MAX,
    # a connection's transformation kinds (kernel.h mk_transform): their codes are their places in
    # the one table of them, master.scenario.model.TRANSFORMATIONS
    **{f"MK_TRANSFORM_{kind.upper()}": code for code, kind in enumerate(TRANSFORMATIONS)},
    # how a loop is solved (kernel.h mk_loop): places in master.scenario.model.LOOP_METHODS
    **{f"MK_LOOP_{m.upper().replace('-', '_')}": code for code, m in enumerate(LOOP_METHODS)},
    "MK_EDGE_ASSUMED": EDGE_ASSUMED,
    "MK_LOOP_STATS": 8,
    # the shared solvers' methods (fmus/fmi/model.h SolverKind 1..SOLVER_COUNT), master.solvers.SOLVERS
    "SOLVER_COUNT": len(SOLVERS),
}
# a loop's counters (kernel.h mk_loop.stats), in their order
LOOP_STATS = ("solves", "iterations", "evaluations", "jacobians", "most", "sequential")

_p = C.c_void_p
_i32, _i64, _u32, _f64 = C.c_int32, C.c_int64, C.c_uint32, C.c_double


class Counter(C.Structure):
    _fields_ = [("value", _i64), ("waiters", _i32), ("pad", _i32 * 13)]


class Shared(C.Structure):
    _fields_ = [
        ("published", C.POINTER(Counter)),
        ("stepped", C.POINTER(Counter)),
        ("consumed", C.POINTER(Counter)),
        ("barrier", C.POINTER(Counter)),
        ("rows_written", C.POINTER(Counter)),
        ("rows_drained", C.POINTER(Counter)),
        ("cancel", C.POINTER(Counter)),
        ("stop_at", C.POINTER(Counter)),
        ("stopper", C.POINTER(_i64)),
        ("busy", C.POINTER(_i64)),
        ("unsettled", C.POINTER(Counter)),
        ("swept", C.POINTER(Counter)),
        ("worker", _i32),
        ("n_workers", _i32),
        ("spin_ns", _i64),
    ]


class Call(C.Structure):
    _fields_ = [
        ("kind", _i32),
        ("first", _i32),
        ("n_values", _i32),
        ("n_vrs", _i32),
        ("vrs", C.POINTER(_u32)),
    ]


class Transform(C.Structure):
    _fields_ = [
        ("kind", _i32),
        ("n_map", _i32),
        ("factor", _f64),
        ("offset", _f64),
        ("from_", C.POINTER(_f64)),
        ("to", C.POINTER(_f64)),
    ]


class Link(C.Structure):
    _fields_ = [
        ("source", _i32),
        ("k_source", _i32),
        ("ahead", _i32),
        ("final", _i32),
        ("n_cols", _i32),
        ("slot0", _i32),
        ("columns", C.POINTER(_i32)),
        ("n_vrs", _i32),
        ("vrs", C.POINTER(_u32)),
        ("terms", _i32),
        ("n_plain", _i32),
        ("n_relaxed", _i32),
        ("offsets", C.POINTER(_i64)),
        ("weights", C.POINTER(_f64)),
        ("zero", C.POINTER(C.c_uint8)),
        ("scale", C.POINTER(_f64)),
        ("predict", C.POINTER(_f64)),
        ("predicted", C.POINTER(_f64)),
        ("error", C.POINTER(_f64)),
        ("transform", C.POINTER(Transform)),
    ]


class Stimulus(C.Structure):
    _fields_ = [
        ("slot", _i32),
        ("kind", _i32),
        ("n", _i32),
        ("times", C.POINTER(_f64)),
        ("values", C.POINTER(_f64)),
        ("start_value", _f64),
    ]


class Intermediate(C.Structure):
    """kernel.h mk_intermediate: the environment of an FMU answered by the kernel's intermediate-update
    callback (`intermediate_update`)."""

    _fields_ = [
        ("component", _p),
        ("u", C.POINTER(_f64)),
        ("t0", _f64),
        ("n", _i32),
        ("slots", C.POINTER(_i32)),
        ("vrs", C.POINTER(_u32)),
        ("values", C.POINTER(_f64)),
        ("status", _i32),
        ("calls", _i64),
    ]


class Scheduled(C.Structure):
    """kernel.h mk_scheduled: a Scheduled Execution component's clocks (master.clocks)."""

    _fields_ = [
        ("n_clocks", _i32),
        ("vrs", C.POINTER(_u32)),
        ("tick", C.POINTER(_i32)),
        ("every", C.POINTER(_i64)),
        ("phase", C.POINTER(_i64)),
        ("first", C.POINTER(_i64)),
        ("points", C.POINTER(_i64)),
        ("due", C.POINTER(_i64)),
        ("activations", C.POINTER(_i64)),
        ("slot", C.POINTER(_i32)),
        ("seen", C.POINTER(_f64)),
        ("activate_model_partition", _p),
        ("get_interval", _p),
    ]


class Component(C.Structure):
    _fields_ = [
        ("fmi", _i32),
        ("instance", _p),
        ("do_step", _p),
        ("set_real", _p),
        ("get_real", _p),
        ("set_derivatives", _p),
        ("get_integer", _p),
        ("get_boolean", _p),
        ("set_integer", _p),
        ("set_boolean", _p),
        ("get_state", _p),
        ("set_state", _p),
        ("free_state", _p),
        ("get_boolean_status", _p),
        ("get_directional_derivative", _p),
        ("get_typed", _p * KINDS),
        ("set_typed", _p * KINDS),
        ("num0", _i64),
        ("dnum", _i64),
        ("den", _i64),
        ("h", _f64),
        ("step_ratio", _i32),
        ("n_in", _i32),
        ("n_in_real", _i32),
        ("n_in_integer", _i32),
        ("n_in_typed", _i32),
        ("in_kinds", C.POINTER(_i32)),
        ("in_vrs", C.POINTER(_u32)),
        ("n_in_calls", _i32),
        ("in_calls", C.POINTER(Call)),
        ("n_blocks", _i32),
        ("n_values", _i32),
        ("feedthrough", _i32),
        ("n_derivatives", _i32),
        ("derivative_vrs", C.POINTER(_u32)),
        ("derivative_orders", C.POINTER(_i32)),
        ("u", C.POINTER(_f64)),
        ("n_links", _i32),
        ("links", C.POINTER(Link)),
        ("n_stimuli", _i32),
        ("stimuli", C.POINTER(Stimulus)),
        ("n_out", _i32),
        ("n_out_real", _i32),
        ("n_out_integer", _i32),
        ("n_out_typed", _i32),
        ("out_kinds", C.POINTER(_i32)),
        ("out_vrs", C.POINTER(_u32)),
        ("n_out_calls", _i32),
        ("out_calls", C.POINTER(Call)),
        ("hist", C.POINTER(_f64)),
        ("hist_previous", C.POINTER(_f64)),
        ("cap", _i32),
        ("reads", C.POINTER(C.c_uint8)),
        ("bound", C.POINTER(_f64)),
        ("resample", _i32),
        ("resample_always", _i32),
        ("resample_outputs", _i32),
        ("resample_texts", _i32),
        ("scratch", C.POINTER(_f64)),
        ("n_consumers", _i32),
        ("consumers", C.POINTER(_i32)),
        ("local", _i32),
        ("get_string", _p),
        ("set_string", _p),
        ("get_binary", _p),
        ("set_binary", _p),
        ("n_out_string", _i32),
        ("n_out_binary", _i32),
        ("out_string_vrs", C.POINTER(_u32)),
        ("strings", C.POINTER(C.c_char)),
        ("strings_previous", C.POINTER(C.c_char)),
        ("n_in_string", _i32),
        ("n_in_binary", _i32),
        ("in_string_vrs", C.POINTER(_u32)),
        ("n_string_links", _i32),
        ("string_links", C.POINTER(Link)),
        ("string_u", C.POINTER(C.c_char)),
        ("saved_state", _p),
        ("steps", C.POINTER(_i64)),
        ("fmu_time", C.POINTER(_f64)),
        ("me", _i32),
        ("me_solver", _i32),
        ("me_substeps", _i32),
        ("n_states", _i32),
        ("set_time", _p),
        ("set_states", _p),
        ("get_states", _p),
        ("get_derivatives", _p),
        ("completed_step", _p),
        ("me_state_vrs", C.POINTER(_u32)),
        ("me_derivative_vrs", C.POINTER(_u32)),
        ("me_x", C.POINTER(_f64)),
        ("me_memory", C.POINTER(_f64)),
        ("me_memory_saved", C.POINTER(_f64)),
        ("me_work", _p),
        ("n_event_indicators", _i32),
        ("get_event_indicators", _p),
        ("enter_event_mode", _p),
        ("update_discrete_states", _p),
        ("enter_continuous_time_mode", _p),
        ("me_next_event", _f64),
        ("me_next_event_saved", _f64),
        ("me_tolerance", _f64),
        ("me_events", _p),
        ("me_event_count", C.POINTER(_i64)),
        ("me_input_events", _i32),
        ("intermediate", C.POINTER(Intermediate)),
        ("scheduled", C.POINTER(Scheduled)),
        ("cs_events", _i32),
        ("enter_step_mode", _p),
        ("cs_stepping", _i32),
        ("n_cs_held", _i32),
        ("cs_late", C.POINTER(C.c_uint8)),
        ("cs_held", C.POINTER(C.c_double)),
        ("cs_held_saved", C.POINTER(C.c_double)),
        ("n_out_clocks", _i32),
        ("out_clock_vrs", C.POINTER(_u32)),
        ("out_clock_ticks", C.POINTER(_i64)),
        ("get_clock", _p),
        ("set_clock", _p),
    ]


class Record(C.Structure):
    _fields_ = [
        ("column", _i32),
        ("component", _i32),
        ("kind", _i32),
        ("index", _u32),
        ("store", _i32),
        ("text", _i32),
    ]


class Error(C.Structure):
    _fields_ = [
        ("code", _i32),
        ("component", _i32),
        ("call", _i32),
        ("status", _i32),
        ("point", _i64),
        ("variable", _i32),
        ("kind", _i32),
        ("value", _f64),
        ("integer", C.c_uint64),
    ]


class Pacing(C.Structure):
    _fields_ = [
        ("factor", _f64),
        ("frame", _f64),
        ("origin_ns", _i64),
        ("n_origin", _i64),
        ("frames", _i64),
        ("overruns", _i64),
        ("worst_ns", _i64),
        ("idle_ns", _i64),
        ("histogram", _i64 * (LATE_BINS + 1)),
    ]


class Loop(C.Structure):
    _fields_ = [
        ("n_members", _i32),
        ("members", C.POINTER(_i32)),
        ("n_unknowns", _i32),
        ("unknown_member", C.POINTER(_i32)),
        ("unknown_column", C.POINTER(_i32)),
        ("unknown_vr", C.POINTER(_u32)),
        ("structure", C.POINTER(C.c_uint8)),
        ("n_inputs", _i32),
        ("input_member", C.POINTER(_i32)),
        ("input_vr", C.POINTER(_u32)),
        ("input_unknown", C.POINTER(_i32)),
        ("input_factor", C.POINTER(_f64)),
        ("method", _i32),
        ("derivatives", _i32),
        ("tolerance", _f64),
        ("max_iterations", _i32),
        ("probed", _i32),
        ("sequential", _i32),
        ("fresh", _i32),
        ("order", C.POINTER(_i32)),
        ("edges", C.POINTER(C.c_uint8)),
        ("reset", C.POINTER(C.c_uint8)),
        ("memory", _i32),
        ("n_history", _i32),
        ("work", C.POINTER(_f64)),
        ("pivot", C.POINTER(_i32)),
        ("stats", C.POINTER(_i64)),
        ("worst", C.POINTER(_f64)),
    ]


class Kernel(C.Structure):
    _fields_ = [
        ("n_components", _i32),
        ("components", C.POINTER(Component)),
        ("n_macro", _i64),
        ("startup_steps", _i64),
        ("startup_sweeps", _i32),
        ("record_every", _i64),
        ("macro_num0", _i64),
        ("macro_dnum", _i64),
        ("macro_den", _i64),
        ("n_columns", _i32),
        ("n_records", _i32),
        ("records", C.POINTER(Record)),
        ("rows", C.POINTER(_f64)),
        ("texts", C.POINTER(C.c_char)),
        ("n_texts", _i32),
        ("row_capacity", _i64),
        ("rows_total", _i64),
        ("rows_drained", _i64),
        ("shared", C.POINTER(Shared)),
        ("barriers", _i64),
        ("n_now", _i64),
        ("stop_at", _i64),
        ("stopper", _i64 * 2),
        ("pacing", C.POINTER(Pacing)),
        ("error", Error),
        ("n_resample_order", _i32),
        ("resample_order", C.POINTER(_i32)),
        ("n_loops", _i32),
        ("loops", C.POINTER(Loop)),
        ("iterate", _i32),
        ("tolerance", _f64),
        ("coupled", C.POINTER(C.c_uint8)),
        ("iterations", C.POINTER(_i64)),
        ("sweeps", _i64),
        ("unsettled_seen", _i64),
    ]


STRUCTS = (Link, Stimulus, Component, Record, Error, Pacing, Kernel, Counter, Shared, Call, Transform, Loop)
STRUCTS += (Intermediate, Scheduled)  # mk_layout's order


class KernelBuildError(RuntimeError):
    """The kernel library is missing and cannot be built here."""


def _built() -> Path | None:
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        p = HERE / f"_kernel{suffix}"
        if p.exists():
            return p
    return None


def _compile() -> Path:
    """Build kernel.c into this package (a development checkout whose library is stale or missing)."""
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise KernelBuildError(f"{SOURCE.name} is not built and no C compiler (cc, gcc) is on PATH")
    target = HERE / f"_kernel{importlib.machinery.EXTENSION_SUFFIXES[0]}"
    fd, tmp = tempfile.mkstemp(dir=HERE, prefix="._kernel", suffix=".so")
    os.close(fd)
    try:
        includes = [f"-I{d}" for d in INCLUDES]
        sources = [str(p) for p in (SOURCE, *SOLVER_SOURCES)]
        run = subprocess.run(
            [cc, *CFLAGS, *includes, "-shared", *sources, "-o", tmp, "-lm"], capture_output=True, text=True
        )
        if run.returncode:
            raise KernelBuildError(f"building {SOURCE.name} failed:\n{run.stderr.strip()}")
        os.chmod(tmp, 0o755)
        os.replace(tmp, target)  # atomic: a concurrent loader sees the old or the new library
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return target


@cache
def library() -> C.CDLL:
    """The kernel library with typed functions, built first where needed."""
    path = _built()
    if CHECKOUT:  # a developer's edit of kernel.c must not run stale code
        solvers = [*SOLVER_SOURCES, FMUS / "solvers" / "solvers.h", FMUS / "fmi" / "model.h"]
        sources = [p.stat().st_mtime for p in (SOURCE, HEADER, SCHEDULED, *solvers) if p.exists()]
        if path is None or (sources and max(sources) > path.stat().st_mtime):
            path = _compile()
    elif path is None:
        raise KernelBuildError(f"{HERE}: the kernel library is missing; reinstall the package")
    lib = C.CDLL(str(path))
    sizes = (_i64 * len(STRUCTS))()
    lib.mk_layout(sizes)
    for struct, size in zip(STRUCTS, sizes, strict=True):
        if C.sizeof(struct) != size:
            raise KernelBuildError(
                f"{path.name}: {struct.__name__} is {size} bytes in C, {C.sizeof(struct)} here"
            )
    values = (_i64 * len(CONSTANTS))()
    lib.mk_constants(values)
    for (name, value), c_value in zip(CONSTANTS.items(), values, strict=True):
        if value != c_value:
            raise KernelBuildError(f"{path.name}: {name} is {c_value} in C, {value} here")
    kp = C.POINTER(Kernel)
    lib.mk_initial_sweep.argtypes = [kp, _i32]
    lib.mk_scheduled_start.argtypes = [kp, _i32]
    lib.mk_record_row.argtypes = [kp, _i64]
    lib.mk_run.argtypes = [kp, _i64, _i64, _f64, C.POINTER(_i64)]
    lib.mk_cancel.argtypes = [C.POINTER(Shared), _i32, _i32]
    lib.mk_cancel.restype = None
    lib.mk_stop.argtypes = [C.POINTER(Shared), _i64, _i32, _i32]
    lib.mk_stop.restype = None
    lib.mk_publish.argtypes = [C.POINTER(Counter), _i64]
    lib.mk_publish.restype = None
    for f in (lib.mk_initial_sweep, lib.mk_scheduled_start, lib.mk_record_row, lib.mk_run):
        f.restype = _i32
    lib.solver_work_new.argtypes = [C.c_int]  # a Model Exchange component's solver work space
    lib.solver_work_new.restype = _p
    lib.solver_work_free.argtypes = [_p]
    lib.solver_work_free.restype = None
    lib.event_work_new.argtypes = [C.c_int, C.c_int]  # its events' scratch
    lib.event_work_new.restype = _p
    lib.event_work_free.argtypes = [_p]
    lib.event_work_free.restype = None
    lib.solver_memory_size.argtypes = [C.c_int]
    lib.solver_memory_size.restype = C.c_size_t
    return lib


def intermediate_update() -> int:
    """The address of the kernel's fmi3IntermediateUpdateCallback (kernel.h mk_intermediate_update)."""
    return C.cast(library().mk_intermediate_update, _p).value
