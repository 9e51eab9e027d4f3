"""One Co-Simulation FMU (FMI 1.0, 2.0 or 3.0) behind a small interface, with fmpy underneath.

The master only ever talks to `Fmu`: it hides whether the FMU is FMI 1, 2 or 3, prepares
value-reference vectors once (`RealPort`), and turns every failing call into an `FmuError`
that names the instance, the FMI function and the FMU's last log message.
Times are in seconds.
"""

from __future__ import annotations

import ctypes
import functools
import math
import os
import shutil
import tempfile
import zipfile
from pathlib import Path

import numpy as np
from fmpy.fmi1 import FMICallException
from fmpy.model_description import ModelDescription

from master.archives import DAMAGED, unsafe
from master.description import (
    FMI3_INTEGERS,
    Variable,
    feedthrough_outputs,
    fmi_function,
    hex_bytes,
    intermediate_inputs,
    lookup,
    parse,
    runs_as_model_exchange,
    runs_as_scheduled,
    typed,
    unsupported,
    uses_event_mode,
    variables_of,
)

DOUBLE_P = ctypes.POINTER(ctypes.c_double)
OK_STATUS = 1  # fmi2Warning / fmi3Warning: a raw call's status above this is a failure
NO_STATE_RESTORED = ctypes.c_int(1)  # doStep's noSetFMUStatePriorToCurrentPoint
_RESET = {1: "fmiResetSlave", 2: "fmi2Reset", 3: "fmi3Reset"}  # by FMI version (1: the slave's)
_FREE = {1: "fmiFreeSlaveInstance", 2: "fmi2FreeInstance", 3: "fmi3FreeInstance"}


class FmuError(Exception):
    """A failing FMU: bad file, bad model description or a failing FMI call."""


def _fmi3_kind(v: Variable) -> str:
    """The FMI 3 type whose calls read and write `v` (an Enumeration is an Int64)."""
    t = v.fmi_type or v.type
    return "Int64" if t == "Enumeration" else t


def _shown(value: object) -> str:
    """A value for an error message: a long Binary by its size and first bytes."""
    if isinstance(value, bytes) and len(value) > 16:
        return f"{len(value)} bytes {value[:8].hex()}..."
    return repr(value)


def read_description(path: Path) -> ModelDescription:
    """Read and check the model description of a Co-Simulation FMU (FMI 1.0, 2.0 or 3.0).

    Read once per file version (path, modification time, size) and process: a run asks for it
    from the planner, the backend and each instance, a sweep from every case. Callers must not
    change the object they get."""
    path = Path(path)
    if not path.is_file():
        raise FmuError(f"{path}: FMU file not found")
    st = path.stat()
    return _read_description(path.resolve(), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=64)
def _read_description(path: Path, _mtime_ns: int, _size: int) -> ModelDescription:
    if not zipfile.is_zipfile(path):
        raise FmuError(f"{path}: not an FMU (not a ZIP archive)")
    try:
        md = parse(path)
    except Exception as e:  # fmpy raises plain Exceptions with the schema error
        raise FmuError(f"{path}: invalid modelDescription.xml: {e}") from e
    why = unsupported(md, path)
    if why:
        raise FmuError(f"{path}: {why}")
    return md


def safe_extract(path: Path, dest: Path) -> Path:
    """Extract what running the FMU archive `path` needs into `dest`, a new folder; refuse unsafe
    members (the check of master.archives) and report damaged data as an FmuError.

    Every member is checked; documentation/, other platforms' binaries and, when this platform's
    binary is there, sources/ are not written (a run extracts each FMU afresh: most of an FMU
    built from C is its sources)."""
    dest = Path(dest).resolve()
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                reason = unsafe(info)
                if reason:
                    raise FmuError(f"{path}: member {info.filename!r}: {reason}")
                # lexical: no member is a link (`unsafe`) and dest is new, so no path resolves elsewhere
                target = os.path.normpath(os.path.join(dest, info.filename))
                if target != str(dest) and not target.startswith(os.path.join(dest, "")):
                    raise FmuError(f"{path}: archive member escapes the extraction folder: {info.filename!r}")
            zf.extractall(dest, members=_needed(zf.namelist()))
    except DAMAGED as err:
        raise FmuError(f"{path}: damaged archive: {err}") from None
    return dest


def _needed(names: list[str]) -> list[str]:
    """The archive members a run of this platform reads."""
    from fmpy import platform, platform_tuple

    ours = (f"binaries/{platform}/", f"binaries/{platform_tuple}/")
    has_binary = any(n.startswith(ours) and not n.endswith("/") for n in names)
    skip = ("documentation/", "binaries/") + (("sources/",) if has_binary else ())
    return [n for n in names if n.startswith(ours) or not n.startswith(skip)]


@functools.cache
def _signatures_once(cls: type) -> type:
    """fmpy's FMI 2 / FMI 3 class `cls`, but reading the C signatures of its FMI functions once per
    class: fmpy reads them with `inspect` from its ~35 Python methods for every instance again (about
    1.4 ms of a run's start per FMU). Where fmpy is not as expected, its own reading stands."""
    signatures: list[tuple[str, list, list, object]] = []

    def _loadFunctions(self) -> None:  # noqa: N802 (fmpy's name)
        if not signatures:
            cls._loadFunctions(self)
            try:
                signatures.extend((n, f.argnames, f.argtypes, f.restype) for n, f in self._functions.items())
            except AttributeError:
                pass
            return
        for name, argnames, argtypes, restype in signatures:  # FMI 2 and 3: the C name is the method's
            f = getattr(self.dll, name)
            f.argnames, f.argtypes, f.restype = argnames, argtypes, restype
            self._functions[name] = f

    # the same name: fmpy tells the FMI versions apart by it
    return type(cls.__name__, (cls,), {"_loadFunctions": _loadFunctions, "__module__": __name__})


# FMI 2 log messages reach the instance through its componentEnvironment, FMI 1 ones (whose logger
# has the same C signature) through the instance pointer or, while it is being instantiated, its
# name: one logger serves all, which fmpy's message-formatting proxy (one per process) needs
_LOGGING: dict[int, Fmu] = {}
_NAMED: dict[bytes, Fmu] = {}  # FMI 1 instances by name
_LOGGER = None


def _fmi2_log(env, instance, status, category, message) -> None:
    fmu = _LOGGING.get(env or 0) or _NAMED.get(instance or b"")
    if fmu is not None:
        fmu.last_log = message.decode("utf-8", "replace") if message else ""
        return
    # Not ours: fmpy's proxy holds one logger per process, now this one, so an FMU that fmpy
    # instantiated with its default callbacks logs here too: print as fmpy's own logger does
    from fmpy.fmi1 import printLogMessage

    printLogMessage(env, instance, status, category, message or b"")


def _fmi2_logger():
    global _LOGGER
    if _LOGGER is None:
        from fmpy.fmi2 import fmi2CallbackLoggerTYPE

        _LOGGER = fmi2CallbackLoggerTYPE(_fmi2_log)
    return _LOGGER


class RealPort:
    """A prepared vector of Real variables: one FMI call moves all values.

    `values` is a preallocated float64 array; `get()` fills it, `set()` sends it.
    `vrs` and `count` are ready-made ctypes arguments for the raw calls of `Fmu`.
    """

    def __init__(self, fmu: Fmu, names: list[str]):
        self.fmu = fmu
        self.names = list(names)
        n = len(self.names)
        self.n = n
        self.vrs = (ctypes.c_uint * max(n, 1))(*[fmu.variables[x].vr for x in self.names])
        self.count = ctypes.c_size_t(n)
        self.values = np.zeros(n)
        self._ptr = self.values.ctypes.data_as(DOUBLE_P)

    def get(self) -> np.ndarray:
        """Read the variables into `values` (one call) and return it."""
        if self.n:
            self.get_into(self._ptr)
        return self.values

    def set(self) -> None:
        """Send `values` to the FMU (one call)."""
        if self.n:
            self.set_from(self._ptr)

    def get_into(self, ptr: object) -> None:
        """Read the variables into the n doubles at ctypes pointer `ptr` (one call)."""
        f = self.fmu
        status = f.raw_get_real(f.handle, self.vrs, self.count, ptr)
        if status > OK_STATUS:
            raise f.call_error("get_real", status)

    def set_from(self, ptr: object) -> None:
        """Send the n doubles at ctypes pointer `ptr` (one call)."""
        f = self.fmu
        status = f.raw_set_real(f.handle, self.vrs, self.count, ptr)
        if status > OK_STATUS:
            raise f.call_error("set_real", status)


class Fmu:
    """One instance of a Co-Simulation FMU.

    Life cycle: `Fmu(path, name)` extracts and loads; `set_values()` for parameters and start
    values; `enter_initialization(start, stop)`, `exit_initialization()`; then `do_step()` (or
    the raw calls of the stepping loop) and `RealPort` get/set; `close()`.
    """

    def __init__(
        self,
        path: Path,
        instance_name: str,
        workdir: Path | None = None,
        model_exchange: bool = False,
        intermediate_update: bool = False,
        scheduled: bool = False,
        event_mode: bool = True,
        unpacked: Path | None = None,
    ):
        """unpacked: a folder where `path` is extracted already (`safe_extract`), shared with its
        other instances: neither extracted again nor removed by `close`."""
        self.path = Path(path)
        self.name = instance_name
        self.md = read_description(self.path)
        self.fmi = int(self.md.fmiVersion[0])  # 1, 2 or 3
        # instantiated for Model Exchange: the kernel integrates its states (kernel.h: mk_component.me)
        # instantiated for Scheduled Execution: the kernel activates its partitions (master.clocks)
        self.scheduled = runs_as_scheduled(self.md, scheduled)
        self.model_exchange = not self.scheduled and runs_as_model_exchange(self.md, model_exchange)
        if self.model_exchange and (self.md.modelExchange is None or self.fmi == 1):
            raise FmuError(f"{instance_name}: {self.path.name} has no Model Exchange 2.0 or 3.0 interface")
        self.fmi3 = self.fmi == 3
        # FMI 3 Co-Simulation with Event Mode (hasEventMode): instantiated with eventModeUsed and early
        # return allowed; the kernel handles its events (kernel.h mk_component.cs_events)
        self.event_mode = event_mode and not self.scheduled and uses_event_mode(self.md, self.model_exchange)
        self.variables = variables_of(self.md)
        self.feedthrough = feedthrough_outputs(self.md)
        self.last_log = ""
        self._own_dir = workdir is None and unpacked is None
        self.dir = unpacked or workdir or Path(tempfile.mkdtemp(prefix=f"fmu_{instance_name}_"))
        self.slave = None
        self._instantiated = False
        self._initialized = False  # FMI 1.0: fmiTerminateSlave only after fmiInitializeSlave
        self._log_key = id(self)  # the componentEnvironment by which the FMI 2 logger finds this instance
        _LOGGING[self._log_key] = self
        # an FMI 3 FMU whose inputs are polynomials (interpolateInputs) and that asks for them inside
        # doStep: the kernel answers its intermediate-update callback (`_instantiate_intermediate`)
        asks = not self.model_exchange and bool(intermediate_inputs(self.md))
        self.intermediate = None
        self._ask = intermediate_update and asks
        try:
            if unpacked is None:
                safe_extract(self.path, self.dir)
            self._load()
        except BaseException:
            self.close()
            raise

    # -- loading ------------------------------------------------------------------------------
    def _load(self) -> None:
        kind = self.md.modelExchange if self.model_exchange else self.md.coSimulation
        kind = self.md.scheduledExecution if self.scheduled else kind
        kw = dict(
            guid=self.md.instantiationToken if self.fmi3 else self.md.guid,
            modelIdentifier=kind.modelIdentifier,
            unzipDirectory=str(self.dir),
            instanceName=self.name,
        )
        try:
            if self.fmi3:
                from fmpy.fmi3 import FMU3Model, FMU3ScheduledExecution, FMU3Slave

                interface = FMU3ScheduledExecution if self.scheduled else FMU3Slave
                self.slave = _signatures_once(FMU3Model if self.model_exchange else interface)(**kw)
            elif self.fmi == 1:
                from fmpy.fmi1 import FMU1Slave

                self.slave = FMU1Slave(**kw)
            else:
                from fmpy.fmi2 import FMU2Model, FMU2Slave

                self.slave = _signatures_once(FMU2Model if self.model_exchange else FMU2Slave)(**kw)
            self._instantiate()
        except FMICallException as e:
            raise FmuError(self.describe(str(e))) from e
        except Exception as e:
            raise FmuError(f"{self.name}: cannot load {self.path.name}: {e}") from e

    def _instantiate_intermediate(self) -> None:
        """fmi3InstantiateCoSimulation as fmpy's instantiate() but with the kernel's intermediate-update
        callback and an environment of its own (native.Intermediate, which fmpy cannot pass), filled
        by the kernel's tables: the FMU asks the kernel for its inputs at its stage times, no Python."""
        from fmpy.fmi3 import fmi3IntermediateUpdateCallback, fmi3LogMessageCallback, fmi3ValueReference

        from master.runtime import native

        s = self.slave
        self.intermediate = native.Intermediate()
        s.logMessage = fmi3LogMessageCallback(self._log3)  # kept from the garbage collector, as fmpy does
        s.intermediateUpdate = fmi3IntermediateUpdateCallback(native.intermediate_update())
        resources = str(Path(s.unzipDirectory) / "resources") + "/"
        s.component = s.fmi3InstantiateCoSimulation(
            self.name.encode("utf-8"),
            s.guid.encode("utf-8"),
            resources.encode("utf-8"),
            False,
            False,
            self.event_mode,  # eventModeUsed
            self.event_mode,  # earlyReturnAllowed
            (fmi3ValueReference * 0)(),
            0,
            ctypes.addressof(self.intermediate),
            s.logMessage,
            s.intermediateUpdate,
        )
        if not s.component:
            raise FmuError(self.describe("fmi3InstantiateCoSimulation failed"))

    def _instantiate(self) -> None:
        """Instantiate the loaded binary (again, after `renew` freed the instance), its log messages
        to `last_log`; bind the raw calls to the new instance."""
        if self.fmi3 and self._ask:
            self._instantiate_intermediate()
        elif self.fmi3 and self.event_mode:
            self.slave.instantiate(logMessage=self._log3, eventModeUsed=True, earlyReturnAllowed=True)
        elif self.fmi3:
            self.slave.instantiate(logMessage=self._log3)
        elif self.fmi == 1:
            self._instantiate1()
        else:
            from fmpy import calloc, free
            from fmpy.fmi2 import (
                fmi2CallbackAllocateMemoryTYPE,
                fmi2CallbackFreeMemoryTYPE,
                fmi2CallbackFunctions,
            )

            cb = fmi2CallbackFunctions()
            cb.logger = _fmi2_logger()
            cb.componentEnvironment = ctypes.c_void_p(self._log_key)
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            try:  # fmpy's native proxy formats the message with its variadic arguments
                from fmpy.logging import addLoggerProxy

                addLoggerProxy(ctypes.byref(cb))
            except (ImportError, OSError, AttributeError):
                pass  # messages then keep their printf placeholders
            self._callbacks = cb  # the FMU keeps the pointer: the structure must live as long
            self.slave.instantiate(callbacks=cb)
        self._instantiated = True
        self._bind_raw()

    def _instantiate1(self) -> None:
        """Instantiate an FMI 1.0 Co-Simulation slave, its log messages to `last_log`."""
        from fmpy import calloc, free
        from fmpy.fmi1 import (
            fmi1CallbackAllocateMemoryTYPE,
            fmi1CallbackFreeMemoryTYPE,
            fmi1CallbackFunctions,
        )

        cb = fmi1CallbackFunctions()
        cb.logger = _fmi2_logger()  # FMI 1's logger type is FMI 2's (same C signature)
        cb.allocateMemory = fmi1CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi1CallbackFreeMemoryTYPE(free)
        cb.stepFinished = None
        try:
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(ctypes.byref(cb))
        except (ImportError, OSError, AttributeError):
            pass
        self._callbacks = cb
        _NAMED[self.name.encode("utf-8")] = self
        self.slave.instantiate(functions=cb)
        if not self.slave.component:
            raise FmuError(self.describe("fmiInstantiateSlave failed"))
        _LOGGING[self.slave.component] = self

    def function_name(self, name: str | None) -> str | None:
        """The exported name of FMI function `name`: FMI 1.0 prefixes the model identifier."""
        if name is None or self.fmi != 1:
            return name
        return f"{self.md.coSimulation.modelIdentifier}_{name}"

    def _log3(self, env, status, category, message) -> None:
        self.last_log = message.decode("utf-8", "replace") if message else ""

    def describe(self, what: str) -> str:
        """`what`, prefixed with the instance name and followed by the FMU's last log message."""
        tail = f" (FMU says: {self.last_log.strip()})" if self.last_log.strip() else ""
        return f"{self.name}: {what}{tail}"

    # -- raw calls for the hot loop ---------------------------------------------------------------
    def _bind_raw(self) -> None:
        """Bind the FMI functions the stepping loop calls, without fmpy's per-call wrapper.

        Each raw_* takes the instance `handle` first and returns the FMI status (an int); get/set
        take (vrs array, count as c_size_t, double pointer) as prepared by `RealPort`; do_step
        takes (t, h) as c_double (s) and c_int 1 (no state restored before t): ctypes objects
        throughout, so that no argument needs converting.
        """
        dll = self.slave.dll
        self.handle = ctypes.c_void_p(self.slave.component)

        def fn(name: str, argtypes: list | None = None):
            f = dll[name]  # a fresh function object: fmpy's own stays untouched
            f.restype = ctypes.c_int
            f.argtypes = argtypes
            return f

        if self.fmi == 1:
            self.raw_get_real = fn(self.function_name("fmiGetReal"))
            self.raw_set_real = fn(self.function_name("fmiSetReal"))
            step1 = fn(
                self.function_name("fmiDoStep"),
                [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_char],
            )

            def do_step1(handle, t: ctypes.c_double, h: ctypes.c_double, _no_set_prior: ctypes.c_int) -> int:
                return step1(handle, t, h, b"\x01")  # newStep: the last step is accepted

            self.raw_do_step = do_step1
            return
        if not self.fmi3:
            self.raw_get_real = fn("fmi2GetReal")
            self.raw_set_real = fn("fmi2SetReal")
            self.raw_do_step = None if self.model_exchange else fn("fmi2DoStep")  # ME: the kernel integrates
            return
        get3, set3 = fn("fmi3GetFloat64"), fn("fmi3SetFloat64")
        if self.model_exchange or self.scheduled:  # no doStep: the kernel integrates or activates
            self.raw_get_real = lambda handle, vrs, count, ptr: get3(handle, vrs, count, ptr, count)
            self.raw_set_real = lambda handle, vrs, count, ptr: set3(handle, vrs, count, ptr, count)
            self.raw_do_step = None
            return
        step3 = fn(
            "fmi3DoStep",
            [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_bool]
            + [ctypes.POINTER(ctypes.c_bool)] * 3
            + [DOUBLE_P],
        )
        flags = [ctypes.c_bool() for _ in range(3)]
        last = ctypes.c_double()
        refs = [ctypes.byref(x) for x in flags] + [ctypes.byref(last)]

        def get_real(handle, vrs, count, ptr) -> int:
            return get3(handle, vrs, count, ptr, count)

        def set_real(handle, vrs, count, ptr) -> int:
            return set3(handle, vrs, count, ptr, count)

        def do_step(handle, t: ctypes.c_double, h: ctypes.c_double, no_set_prior: ctypes.c_int) -> int:
            status = step3(handle, t, h, bool(no_set_prior.value), *refs)
            if status <= OK_STATUS and flags[1].value:  # terminateSimulation
                raise FmuError(self.describe(f"asked to terminate at t={t.value + h.value}"))
            return status

        self.raw_get_real, self.raw_set_real, self.raw_do_step = get_real, set_real, do_step

    def call_error(self, call: str, status: int) -> FmuError:
        """The FmuError for raw call `call` ("get_real", "set_real", "do_step", ...) returning `status`."""
        name = self.function_name(fmi_function(call, self.fmi))
        return FmuError(self.describe(str(FMICallException(function=name, status=status))))

    def real_port(self, names: list[str]) -> RealPort:
        """A prepared vector of Real variables (names must exist and be Real)."""
        for n in names:
            v = self.variables.get(n)
            if v is None:
                raise FmuError(f"{self.name}: no variable {n!r} in {self.path.name}")
            if v.type != "Real" or v.shape:
                raise FmuError(
                    f"{self.name}.{n}: type {v.type}{list(v.shape) or ''}, a scalar Real is needed here"
                )
        return RealPort(self, names)

    # -- typed values (set-up, recording of non-Real variables) ---------------------------------
    def set_values(self, values: dict[str, object]) -> None:
        """Set parameters / start values by name, converting each to the variable's type. An
        element of an FMI 3 array is named y[i,j] (master.description.element_names): the
        array is set whole, its other elements at their start values."""
        arrays: dict[str, tuple[Variable, dict[int, object]]] = {}
        for name, value in values.items():
            found = lookup(self.variables, name)
            if found is None:
                raise FmuError(f"{self.name}: no variable {name!r} in {self.path.name}")
            v, position = found
            if v.causality in ("calculatedParameter", "independent") or v.variability == "constant":
                raise FmuError(f"{self.name}.{name}: a {v.causality} {v.variability} variable cannot be set")
            if v.shape and position is None:
                raise FmuError(
                    f"{self.name}.{name} is an array ({typed(v.fmi_type, v.shape)}): set its elements, "
                    f"{name}[...], one by one"
                )
            if position is not None:
                arrays.setdefault(v.name, (v, {}))[1][position] = value
                continue
            try:
                self._set_one(v, value)
            except FMICallException as e:
                raise FmuError(self.describe(f"cannot set {name} = {_shown(value)}: {e}")) from e
        for v, elements in arrays.values():
            try:
                self._set_array(v, elements)
            except FMICallException as e:
                raise FmuError(self.describe(f"cannot set {v.name}: {e}")) from e

    def _set_array(self, v: Variable, elements: dict[int, object]) -> None:
        """An FMI 3 array through one call of its type: the elements given (position in row-major
        order -> value), the others at their start values."""
        kind = _fmi3_kind(v)
        if kind in ("String", "Binary"):
            raise FmuError(f"{self.name}.{v.name}: arrays of type {v.fmi_type} are not supported")
        starts = (v.start or "").split()
        if len(starts) != v.size:
            raise FmuError(f"{self.name}.{v.name}: {len(starts)} start values for {v.size} elements")
        values = [self._converted(v, kind, x) for x in starts]
        for position, value in elements.items():
            values[position] = self._converted(v, kind, value)
        getattr(self.slave, f"set{kind}")([v.vr], values)

    def _set_one(self, v: Variable, value: object) -> None:
        """One value through the call of the variable's own type (FMI 3: Float32, Int8 ... UInt64,
        Enumeration as Int64 too, Binary through fmi3SetBinary)."""
        kind = _fmi3_kind(v) if self.fmi3 else v.type
        x = self._converted(v, kind, value)
        name = "Integer" if kind == "Enumeration" else kind  # (in FMI 3 _fmi3_kind says Int64)
        getattr(self.slave, f"set{name}")([v.vr], [x])

    def _converted(self, v: Variable, kind: str, value: object) -> object:
        """`value` (a number, a bool, text from a start attribute or a binding, bytes) as the set
        call of `kind` takes it; FmuError if it is not one."""
        if kind in ("Real", "Float64", "Float32"):
            return float(value)  # type: ignore[arg-type]
        if kind in ("Integer", "Enumeration") or kind in FMI3_INTEGERS:
            if isinstance(value, float) and not value.is_integer():
                raise FmuError(f"{self.name}.{v.name}: {value!r} is not an integer")
            return int(value)  # type: ignore[arg-type]
        if kind == "Boolean":
            if not isinstance(value, str):
                return bool(value)
            if value.lower() not in ("true", "false", "1", "0"):
                raise FmuError(f"{self.name}.{v.name}: {value!r} is not a Boolean")
            return value.lower() in ("true", "1")
        if kind == "String":
            return str(value)
        if kind == "Binary":
            return self._bytes(v, value)
        raise FmuError(f"{self.name}.{v.name}: variables of type {v.fmi_type or v.type} are not supported")

    def _bytes(self, v: Variable, value: object) -> bytes:
        """A Binary value: bytes as they are, text as hex digits (a Scenario built in Python, or
        set_values given as text)."""
        if isinstance(value, (bytes, bytearray)):
            return bytes(value)
        if isinstance(value, str):
            try:
                return hex_bytes(value)
            except ValueError:
                pass
        raise FmuError(
            f"{self.name}.{v.name}: {value!r} is not a Binary value (bytes, or hex digits as text)"
        )

    # -- life cycle --------------------------------------------------------------------------
    def enter_initialization(self, start: float, stop: float) -> None:
        """Enter initialisation mode for the experiment [start, stop] (s). FMI 1.0 has no such mode:
        its slave is initialised here (fmiInitializeSlave, with the parameters and start values set
        so far), after which inputs may be set and outputs read at the start time as FMI 2 does in
        initialisation mode."""
        try:
            if self.fmi == 1:
                self._initialize1(start, stop)
            elif self.fmi3:
                self.slave.enterInitializationMode(startTime=start, stopTime=stop)
            else:
                self.slave.setupExperiment(startTime=start, stopTime=stop)
                self.slave.enterInitializationMode()
        except FMICallException as e:
            raise FmuError(self.describe(f"initialisation failed: {e}")) from e

    def _initialize1(self, start: float, stop: float) -> None:
        f = self.slave.dll[self.function_name("fmiInitializeSlave")]  # fmpy's own has no status type
        f.restype = ctypes.c_int
        f.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_char, ctypes.c_double]
        status = f(self.slave.component, start, b"\x01", stop)
        if status > OK_STATUS:
            raise FMICallException(function=self.function_name("fmiInitializeSlave"), status=status)
        self._initialized = True

    def exit_initialization(self) -> None:
        """Leave initialisation mode; the FMU is then ready to step (FMI 1.0: it already is)."""
        if self.fmi == 1:
            return
        try:
            self.slave.exitInitializationMode()
            if self.model_exchange:
                self._continuous_time()
            elif self.event_mode:  # in Event Mode after initialisation
                self._discrete_states()
                self.slave.enterStepMode()
        except FMICallException as e:
            raise FmuError(self.describe(f"initialisation failed: {e}")) from e

    def _continuous_time(self) -> None:
        """A Model Exchange FMU after initialisation: the event iteration, then continuous-time mode."""
        self._discrete_states()
        self.slave.enterContinuousTimeMode()

    def _discrete_states(self) -> None:
        """The event iteration after initialisation: new discrete states until none are needed."""
        for _ in range(1000):
            if self.fmi3:
                needed, terminate, *_, timed, when = self.slave.updateDiscreteStates()
            else:
                needed, terminate, *_, timed, when = self.slave.newDiscreteStates()
            self.next_event_time = when if timed else math.inf  # the kernel meets it (kernel.h me_next_event)
            if terminate:
                raise FmuError(self.describe("ends the simulation at its initialisation"))
            if not needed:
                break
        else:
            raise FmuError(self.describe("its event iteration after initialisation never ends (1000 rounds)"))

    def get_state(self) -> object:
        """A saved copy of the FMU state (canGetAndSetFMUstate); free it with `free_state`."""
        if self.fmi == 1:
            raise FmuError(self.describe("FMI 1.0 cannot save the FMU state"))
        try:
            return self.slave.getFMUState() if self.fmi3 else self.slave.getFMUstate()
        except FMICallException as e:
            raise FmuError(self.describe(f"cannot save the FMU state: {e}")) from e

    def set_state(self, state: object) -> None:
        """Restore a state saved by `get_state`."""
        try:
            self.slave.setFMUState(state) if self.fmi3 else self.slave.setFMUstate(state)
        except FMICallException as e:
            raise FmuError(self.describe(f"cannot restore the FMU state: {e}")) from e

    def free_state(self, state: object) -> None:
        try:
            self.slave.freeFMUState(state) if self.fmi3 else self.slave.freeFMUstate(state)
        except FMICallException as e:
            raise FmuError(self.describe(f"cannot free the FMU state: {e}")) from e

    def do_step(self, t: float, h: float) -> None:
        """Advance from communication point t by h (s); FmuError if the FMU refuses."""
        status = self.raw_do_step(self.handle, ctypes.c_double(t), ctypes.c_double(h), NO_STATE_RESTORED)
        if status > OK_STATUS:
            raise self.call_error("do_step", status)

    def renew(self) -> bool:
        """Back to the state after instantiation, every variable at its start value, for another
        run of the loaded binary: fmi2Reset, fmi3Reset or fmiResetSlave (after fmiTerminateSlave);
        where that fails, the instance is freed and instantiated again. True when the instance is
        a new one (its handle changed); FmuError when it cannot be had either way."""
        self.last_log = ""
        if self.fmi == 1 and self._initialized:
            self._raw("fmiTerminateSlave")  # a refusal just leads to a new instance
        self._initialized = False
        reset = self._raw(_RESET[self.fmi])
        if reset is not None and reset <= OK_STATUS:
            return False
        free = self.slave.dll[self.function_name(_FREE[self.fmi])]
        free.restype, free.argtypes = None, [ctypes.c_void_p]
        if self.fmi == 1:
            _LOGGING.pop(self.slave.component, None)
        free(self.slave.component)
        self._instantiated = False
        try:
            self._instantiate()
        except Exception as e:
            raise FmuError(f"{self.name}: cannot instantiate {self.path.name} again: {e}") from e
        return True

    def _raw(self, name: str) -> int | None:
        """The status of FMI function `name` called with the instance alone; None if not exported."""
        try:
            f = self.slave.dll[self.function_name(name)]
        except AttributeError:
            return None
        f.restype, f.argtypes = ctypes.c_int, [ctypes.c_void_p]
        return f(self.slave.component)

    def close(self) -> None:
        """Terminate, free the instance and remove the extracted files; safe to call twice."""
        s, self.slave = self.slave, None
        if s is not None:
            if self._instantiated:
                try:
                    if self.fmi != 1 or self._initialized:
                        s.terminate()
                except Exception:
                    pass  # a failed FMU may refuse to terminate; free it anyway
                try:
                    s.freeInstance()
                except Exception:
                    pass
            else:
                try:
                    s.freeLibrary()
                except Exception:
                    pass
        _LOGGING.pop(self._log_key, None)
        if self.fmi == 1:
            for key in [k for k, f in _LOGGING.items() if f is self]:
                del _LOGGING[key]
            if _NAMED.get(self.name.encode("utf-8")) is self:
                del _NAMED[self.name.encode("utf-8")]
        if self._own_dir and self.dir.exists():
            shutil.rmtree(self.dir, ignore_errors=True)
