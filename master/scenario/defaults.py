"""Settings for a scenario that carries no settings annotation of ours (a file written by another
tool): the macro step from the command line, else from another tool's step hint in the file, else
from the FMUs' own DefaultExperiment stepSize; every other setting keeps its default (Jacobi,
extrapolation order 0, all outputs recorded); a Model Exchange component is integrated with the
default method and step (settings.DEFAULT_MODEL_EXCHANGE).

Each component communicates at its own preferred step (libcosim's StepSizeHint, else its FMU's
stepSize) where that step divides the macro step, else once per macro step.
"""

from __future__ import annotations

from fractions import Fraction

from lxml import etree

from .context import Context
from .numbers import parse_time
from .problems import NS_SSC, NS_SSD
from .settings import MAX_STEP_RATIO, Settings, limit_problems, model_exchange, seconds, steps_problem
from .xmlio import tag

OSP = "com.opensimulationplatform"  # libcosim / ecos (Open Simulation Platform)
OMS = "org.openmodelica"  # OMSimulator
# (annotation type, element local name, attribute) that give the master's step of the whole system
SYSTEM_HINTS = ((OSP, "FixedStepAlgorithm", "baseStepSize"), (OMS, "FixedStepMaster", "stepSize"))
HOW = "give --macro-step H (seconds) or add the settings annotation (docs/scenario-format.md)"


def choose(
    ctx: Context,
    root: etree._Element,
    system: etree._Element,
    times: tuple[Fraction, Fraction] | None,
    macro_step: Fraction | None = None,
) -> Settings | None:
    """Settings without our annotation, or None after a problem saying how to give a macro step."""
    own = {name: _component_step(ctx, name) for name in ctx.comps}  # name -> (step, where) or None
    if macro_step is not None:
        macro, origin = macro_step, "command line (--macro-step)"
    else:
        hint = _system_hint(ctx, root)
        macro, origin = hint if hint is not None else _from_fmus(ctx, root, own)
    if macro is None:
        return None
    s = Settings(macro_step=macro)
    s.origins["macro step"] = origin
    for name, found in own.items():
        s.step_ratio[name] = 1
        s.extrapolation_order[name] = 0
        s.interpolate_inputs[name] = False
        s.origins[f"{name} communication step"] = "the macro step"
        if found is None:
            continue
        step, where = found
        k = macro / step
        if k.denominator == 1 and 1 < k <= MAX_STEP_RATIO:
            s.step_ratio[name] = int(k)
            s.origins[f"{name} communication step"] = where
        elif k != 1:
            why = "does not divide it" if k.denominator != 1 or k < 1 else f"is 1/{k} of it: too fine"
            s.origins[f"{name} communication step"] = f"the macro step ({where} {seconds(step)} {why})"
    for name, comp in ctx.comps.items():  # implementation="ModelExchange", or an FMU with only that
        model_exchange(ctx, comp.elem, {}, s, name, comp.info)
    if times is not None:
        exp = root.find(tag(NS_SSD, "DefaultExperiment"))
        whole = steps_problem(times[1] - times[0], macro)
        for problem in ([f"stopTime - startTime = {whole}"] if whole else []) + limit_problems(
            *times, macro, s.step_ratio
        ):
            ctx.at(exp if exp is not None else root, problem)
    return s


def _step(ctx: Context, elem: etree._Element, attr: str) -> Fraction | None:
    """A positive step attribute of another tool's element; None (a problem said) if unusable."""
    try:
        step = parse_time(elem.get(attr, ""))
    except ValueError as e:
        ctx.at(elem, f"{attr}: {e}")
        return None
    if step <= 0:
        ctx.at(elem, f"{attr} must be positive")
        return None
    return step


def _system_hint(ctx: Context, root: etree._Element) -> tuple[Fraction | None, str] | None:
    """The first fixed master step another tool wrote on a system or the default experiment."""
    for ann in root.iter(tag(NS_SSC, "Annotation")):
        holder = ann.getparent().getparent()
        if holder.tag not in (tag(NS_SSD, "System"), tag(NS_SSD, "DefaultExperiment")):
            continue
        for kind, local, attr in SYSTEM_HINTS:
            if ann.get("type") != kind:
                continue
            for elem in ann.iter():
                if isinstance(elem.tag, str) and etree.QName(elem).localname == local and elem.get(attr):
                    return _step(ctx, elem, attr), f'the file\'s "{kind}" annotation ({local} {attr})'
    return None


def _component_step(ctx: Context, name: str) -> tuple[Fraction, str] | None:
    """A component's preferred communication step: libcosim's StepSizeHint on the component, else
    its FMU's DefaultExperiment stepSize; None if neither gives one."""
    comp = ctx.comps[name]
    for ann in comp.elem.findall(f"{tag(NS_SSD, 'Annotations')}/{tag(NS_SSC, 'Annotation')}"):
        if ann.get("type") == OSP:
            for elem in ann.iter():
                if isinstance(elem.tag, str) and etree.QName(elem).localname == "StepSizeHint":
                    step = _step(ctx, elem, "value")
                    return None if step is None else (step, "its StepSizeHint")
    if comp.info is None:
        return None
    text = fmu_step(comp.info.path)
    try:
        step = parse_time(text) if text else None
    except ValueError:
        step = None  # a stepSize no master could use: the FMU gives no preference
    return (step, "its FMU's stepSize") if step is not None and step > 0 else None


def fmu_step(path) -> str | None:
    """The DefaultExperiment stepSize an FMU's model description gives, as written."""
    from master.description import parse

    try:
        experiment = parse(path).defaultExperiment
    except Exception:  # noqa: BLE001 -- an unreadable description gives no step; fmuinfo says why
        return None
    return getattr(experiment, "stepSize", None) if experiment is not None else None


def _from_fmus(
    ctx: Context, root: etree._Element, own: dict[str, tuple[Fraction, str] | None]
) -> tuple[Fraction | None, str]:
    """The largest of the components' own steps if every other divides it; else a problem."""
    steps = {name: found[0] for name, found in own.items() if found is not None}
    if not steps:
        ctx.at(root, f"no macro step: no settings annotation, step hint or FMU stepSize gives one; {HOW}")
        return None, ""
    macro = max(steps.values())
    odd = [n for n, h in steps.items() if (macro / h).denominator != 1]
    if odd:
        listed = ", ".join(f"{n} {seconds(h)}" for n, h in steps.items())
        ctx.at(root, f"no macro step: the components' own steps ({listed}) do not all divide the "
                     f"largest; {HOW}")  # fmt: skip
        return None, ""
    return macro, "the largest of the components' own steps (FMU stepSize or StepSizeHint)"
