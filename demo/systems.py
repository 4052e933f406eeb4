"""The closed loop of PiezoController and FlexureStage packaged for other tools.

`python -m demo.systems --dist dist` (what `make systems` runs) writes:

- dist/PiezoStageSystem.ssp, an SSP 1.0 package: SystemStructure.ssd with both
  FMUs (resources/*.fmu) as components `plant` and `controller`, their
  connections and, for each, a parameter binding to an .ssv parameter set
  (resources/plant.ssv, resources/controller.ssv). For OMSimulator,
  libcosim, fmpy's SSP support and any SSP 1.0 importer.
- dist/PiezoStageLoop.fmu, the same loop as one FMI 2.0 co-simulation FMU: a
  container FMU (fmpy's container runtime, built with
  fmpy.container_fmu.create_container_fmu) holding both FMUs, with inputs
  x_ref, y_ref, theta_ref, the outputs of both FMUs, and every parameter of
  both under `plant.` and `controller.`.

Nothing is written twice by hand: variable names, types, causalities and units
come from the two FMUs' modelDescription.xml (generated from the Rust variable
tables), the wiring from demo.cosim (COMMANDS, SENSORS, REFERENCES), and the
parameter values from dist/presets/*.json (written by `make fmus` from the
Rust parameter structs) with the demo's run conditions on top.

The system configuration (SYSTEM_PRESETS + SYSTEM_OVERRIDES): FlexureStage's
3dof set with the demo's seeded sensor noise on (demo.experiments.
PLANT_PARAMETERS), PiezoController's stage set, and the references held at the
demo's home pose (demo.experiments.MID_STROKE). Loaded as is, both the SSP and the
container FMU run the stage from rest to home and hold it there with feedback
on every axis, at the controller's 10 kHz.

Why the references are not SSP connectors: fmpy 0.3.32's SSP master writes
every declared input connector before each step (0 when it is unconnected),
which would override the .ssv's home pose; and libcosim 0.0.6's SSP parser
accepts connections between components only (no system connectors). Left
undeclared, they keep the start values of the .ssv in every importer, and
libcosim and OMSimulator can still set them by name.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path

from fmpy import read_model_description
from fmpy.model_description import (
    CoSimulation,
    DefaultExperiment,
    ModelDescription,
    ModelVariable,
    Unknown,
)
from lxml import etree

from demo.cosim import (
    COMMANDS,
    CONTROLLER_INSTANCE,
    PLANT_INSTANCE,
    REFERENCES,
    SAMPLE_PERIOD,
    SENSORS,
)
from demo.experiments import MID_STROKE, PLANT_PARAMETERS

SYSTEM_NAME = "PiezoStageSystem"
LOOP_NAME = "PiezoStageLoop"
#: Default experiment of both: 1 s (the FMUs' own DefaultExperiment) at 10 kHz.
STOP_TIME = 1.0

#: instance -> (FMU identifier, preset file under dist/presets)
SYSTEM_PRESETS = {
    PLANT_INSTANCE: ("FlexureStage", "FlexureStage.3dof.json"),
    CONTROLLER_INSTANCE: ("PiezoController", "PiezoController.stage.json"),
}
#: What the system sets on top of the presets: the demo's conditions.
SYSTEM_OVERRIDES = {
    PLANT_INSTANCE: dict(PLANT_PARAMETERS),
    CONTROLLER_INSTANCE: dict(zip(REFERENCES, MID_STROKE)),
}

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
#: libcosim reads its fixed-step algorithm from this DefaultExperiment annotation.
OSP_ANNOTATION = "com.opensimulationplatform"


class SystemMismatch(ValueError):
    """The FMUs, presets and wiring do not fit together."""


@dataclass
class Member:
    """One FMU of the system, as an instance with its parameter set."""

    instance: str
    fmu: Path
    description: object  # fmpy ModelDescription
    parameters: dict  # name -> value (bool, int or float by the FMU's declared type)

    @property
    def variables(self) -> dict:
        return {v.name: v for v in self.description.modelVariables}


def connections() -> list[tuple[str, str, str, str]]:
    """(start instance, output, end instance, input) for every wire."""
    return [(CONTROLLER_INSTANCE, s, PLANT_INSTANCE, d) for s, d in COMMANDS] + [
        (PLANT_INSTANCE, s, CONTROLLER_INSTANCE, d) for s, d in SENSORS
    ]


def _typed(variable, value, where: str):
    if variable.type == "Real":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SystemMismatch(f"{where}: Real expected, got {value!r}")
        return float(value)
    if variable.type == "Integer":
        if isinstance(value, bool) or not isinstance(value, int):
            raise SystemMismatch(f"{where}: Integer expected, got {value!r}")
        return value
    if variable.type == "Boolean":
        if not isinstance(value, bool):
            raise SystemMismatch(f"{where}: Boolean expected, got {value!r}")
        return value
    raise SystemMismatch(f"{where}: unsupported type {variable.type}")


def load_members(dist: Path) -> list[Member]:
    """Both FMUs with the system's parameter sets, checked against their
    model descriptions (every name exists, is a parameter or, for the
    references, an input, and has the declared type)."""
    members = []
    for instance, (identifier, preset) in SYSTEM_PRESETS.items():
        fmu = dist / f"{identifier}.fmu"
        preset_path = dist / "presets" / preset
        for path in (fmu, preset_path):
            if not path.is_file():
                raise SystemMismatch(f"{path} is missing: run `make fmus` first")
        description = read_model_description(str(fmu))
        variables = {v.name: v for v in description.modelVariables}
        values = json.loads(preset_path.read_text()) | SYSTEM_OVERRIDES[instance]
        parameters = {}
        for name, value in values.items():
            where = f"{preset_path.name} / {identifier}.{name}"
            variable = variables.get(name)
            if variable is None:
                raise SystemMismatch(f"{where}: no such variable in {fmu.name}")
            if variable.causality not in ("parameter", "input"):
                raise SystemMismatch(f"{where}: causality {variable.causality}, not settable")
            parameters[name] = _typed(variable, value, where)
        members.append(Member(instance, fmu, description, parameters))
    by_instance = {m.instance: m for m in members}
    for start, output, end, input_ in connections():
        source = by_instance[start].variables.get(output)
        target = by_instance[end].variables.get(input_)
        wire = f"{start}.{output} -> {end}.{input_}"
        if source is None or source.causality != "output":
            raise SystemMismatch(f"{wire}: {output} is not an output of {by_instance[start].fmu.name}")
        if target is None or target.causality != "input":
            raise SystemMismatch(f"{wire}: {input_} is not an input of {by_instance[end].fmu.name}")
        if source.type != target.type:
            raise SystemMismatch(f"{wire}: {source.type} to {target.type}")
    return members


def literal(value) -> str:
    """An XML Schema / FMI literal: xs:boolean, xs:int, xs:double (repr
    round-trips every double exactly)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _xml(root) -> bytes:
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def parameter_set_xml(member: Member, name: str) -> bytes:
    """The member's parameter set as an SSP 1.0 .ssv (names relative to the
    component, as a component's ParameterBinding reads them)."""
    root = etree.Element(_q("ssv", "ParameterSet"), nsmap={"ssv": NS["ssv"]})
    root.set("version", "1.0")
    root.set("name", name)
    parameters = etree.SubElement(root, _q("ssv", "Parameters"))
    variables = member.variables
    for key, value in member.parameters.items():
        parameter = etree.SubElement(parameters, _q("ssv", "Parameter"), name=key)
        etree.SubElement(parameter, _q("ssv", variables[key].type), value=literal(value))
    return _xml(root)


def _connector_names(member: Member) -> list[str]:
    """Every input and output except the references (see the module doc)."""
    return [
        v.name
        for v in member.description.modelVariables
        if v.causality in ("input", "output") and v.name not in REFERENCES
    ]


def system_structure_xml(members: list[Member], ssv_sources: dict[str, str]) -> bytes:
    root = etree.Element(
        _q("ssd", "SystemStructureDescription"),
        nsmap={k: NS[k] for k in ("ssd", "ssc", "osp")},
    )
    root.set("version", "1.0")
    root.set("name", SYSTEM_NAME)
    root.set("generationTool", "piezo-fmu demo.systems")
    system = etree.SubElement(root, _q("ssd", "System"), name=SYSTEM_NAME)
    system.set(
        "description",
        "PiezoController and FlexureStage in closed loop: u1..u3 drive the amplifier channels, "
        "s1..s3 feed the controller; the references x_ref, y_ref, theta_ref are held at the "
        "start values of controller.ssv",
    )
    elements = etree.SubElement(system, _q("ssd", "Elements"))
    units_used = {}
    for member in members:
        component = etree.SubElement(
            elements,
            _q("ssd", "Component"),
            name=member.instance,
            type="application/x-fmu-sharedlibrary",
            source=f"resources/{member.fmu.name}",
        )
        connectors = etree.SubElement(component, _q("ssd", "Connectors"))
        for name in _connector_names(member):
            variable = member.variables[name]
            connector = etree.SubElement(
                connectors, _q("ssd", "Connector"), name=name, kind=variable.causality
            )
            typed = etree.SubElement(connector, _q("ssc", variable.type))
            if variable.unit:
                typed.set("unit", variable.unit)
                units_used[variable.unit] = _unit(member.description, variable.unit)
        bindings = etree.SubElement(component, _q("ssd", "ParameterBindings"))
        etree.SubElement(
            bindings, _q("ssd", "ParameterBinding"), source=ssv_sources[member.instance]
        )
    wires = etree.SubElement(system, _q("ssd", "Connections"))
    for start, output, end, input_ in connections():
        etree.SubElement(
            wires,
            _q("ssd", "Connection"),
            startElement=start,
            startConnector=output,
            endElement=end,
            endConnector=input_,
        )
    if units_used:
        units = etree.SubElement(root, _q("ssd", "Units"))
        for name, unit in units_used.items():
            element = etree.SubElement(units, _q("ssc", "Unit"), name=name)
            base = etree.SubElement(element, _q("ssc", "BaseUnit"))
            for key in ("kg", "m", "s", "A", "K", "mol", "cd", "rad"):
                exponent = getattr(unit.baseUnit, key, 0) if unit.baseUnit else 0
                if exponent:
                    base.set(key, str(exponent))
            if unit.baseUnit and unit.baseUnit.factor != 1.0:
                base.set("factor", literal(unit.baseUnit.factor))
            if unit.baseUnit and unit.baseUnit.offset != 0.0:
                base.set("offset", literal(unit.baseUnit.offset))
    experiment = etree.SubElement(
        root, _q("ssd", "DefaultExperiment"), startTime="0", stopTime=literal(STOP_TIME)
    )
    annotations = etree.SubElement(experiment, _q("ssd", "Annotations"))
    annotation = etree.SubElement(annotations, _q("ssc", "Annotation"), type=OSP_ANNOTATION)
    algorithm = etree.SubElement(annotation, _q("osp", "Algorithm"))
    etree.SubElement(
        algorithm, _q("osp", "FixedStepAlgorithm"), baseStepSize=literal(SAMPLE_PERIOD)
    )
    return _xml(root)


def _unit(description, name: str):
    for unit in description.unitDefinitions:
        if unit.name == name:
            return unit
    raise SystemMismatch(f"unit {name!r} used but not defined in {description.modelName}")


def _write_zip(path: Path, entries: list[tuple[str, bytes]]) -> None:
    """A zip with fixed timestamps, so that the same inputs give the same bytes."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_suffix(path.suffix + ".part")
    with zipfile.ZipFile(temporary, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in entries:
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, data)
    temporary.replace(path)


def write_ssp(members: list[Member], out: Path) -> Path:
    ssv_sources = {m.instance: f"resources/{m.instance}.ssv" for m in members}
    entries = [("SystemStructure.ssd", system_structure_xml(members, ssv_sources))]
    for member in members:
        preset = SYSTEM_PRESETS[member.instance][1].removesuffix(".json")
        entries.append((ssv_sources[member.instance], parameter_set_xml(member, preset)))
        entries.append((f"resources/{member.fmu.name}", member.fmu.read_bytes()))
    _write_zip(out, entries)
    return out


# --------------------------------------------------------------------------
# container FMU
# --------------------------------------------------------------------------


def _copy_variable(variable, name: str, start=None) -> ModelVariable:
    # FMI 2.0.4 §2.2.7: an input carries no `initial` (fmpy reads the
    # default "exact" into one); canHandleMultipleSetPerTimeInstant is a
    # Model Exchange input's attribute, and the container is Co-Simulation.
    return ModelVariable(
        name=name,
        type=variable.type,
        causality=variable.causality,
        variability=variable.variability,
        initial=None if variable.causality in ("input", "independent") else variable.initial,
        canHandleMultipleSetPerTimeInstant=False,  # False: fmpy writes no attribute
        description=variable.description,
        unit=variable.unit,
        # The inner FMUs' ranges and display units, which importers' dialogs
        # show (FMI 2.0.4 §2.2.7); the inner FMUs still refuse a value out of
        # range, but the container dropped them.
        displayUnit=variable.displayUnit,
        min=variable.min,
        max=variable.max,
        nominal=variable.nominal,
        start=start,
    )


def container_configuration(members: list[Member]):
    """fmpy's container Configuration: ports without prefix (their names do
    not clash), parameters under `<instance>.`, start values = the system's
    parameter sets."""
    from fmpy.container_fmu.config import Component, Configuration, Connection

    by_instance = {m.instance: m for m in members}
    components = {
        m.instance: Component(name=m.instance, filename=m.fmu, modelDescription=m.description)
        for m in members
    }
    time = ModelVariable(name="time", type="Real", causality="independent", variability="continuous",
                         canHandleMultipleSetPerTimeInstant=False)
    # fmpy's container runtime takes value reference 0 for the time (without
    # it every variable reads its neighbour's value). libcosim's FMI Library
    # logs two "[error] Start attribute is required" lines for it on loading
    # (FMI 2.0 allows an independent variable without one); the run is right.
    variables = [time]
    mappings = {}
    outputs = []
    # (instance, inner name) -> the container's variable, for dependencies.
    exposed_as = {}

    def expose(member: Member, variable, name: str):
        start = member.parameters.get(variable.name)
        if start is None and variable.causality in ("parameter", "input"):
            start = variable.start
        start = None if start is None else (
            literal(start) if not isinstance(start, str) else start
        )
        exposed = _copy_variable(variable, name, start)
        variables.append(exposed)
        mappings[exposed] = [(components[member.instance], variable)]
        exposed_as[member.instance, variable.name] = exposed
        if variable.causality == "output":
            outputs.append((exposed, member, variable))

    controller = by_instance[CONTROLLER_INSTANCE]
    for name in REFERENCES:
        expose(controller, controller.variables[name], name)
    port_names = set(REFERENCES)
    for member in members:
        for variable in member.description.modelVariables:
            if variable.causality == "output":
                if variable.name in port_names:
                    raise SystemMismatch(f"output {variable.name} exists in both FMUs")
                port_names.add(variable.name)
                expose(member, variable, variable.name)
    for member in members:
        for variable in member.description.modelVariables:
            if variable.causality == "parameter":
                expose(member, variable, f"{member.instance}.{variable.name}")

    def runtime_typed(variable):
        # fmpy 0.3.32 writes an FMI 2.0 connection's type as the FMI 2.0 name
        # ("Real"), which its runtime does not parse (it wants the FMI 3.0
        # names and moves Float64 through fmi2GetReal/fmi2SetReal for FMI 2.0
        # components). Variables are mapped; connections are not.
        names = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
        copy = _copy_variable(variable, variable.name)
        copy.type = names[variable.type]
        copy.valueReference = variable.valueReference
        return copy

    wires = []
    for start, output, end, input_ in connections():
        wires.append(
            Connection(
                components[start],
                [runtime_typed(by_instance[start].variables[output])],
                components[end],
                [runtime_typed(by_instance[end].variables[input_])],
            )
        )

    units = {}
    for member in members:
        for unit in member.description.unitDefinitions:
            units.setdefault(unit.name, unit)
    guid_source = "|".join(
        [m.description.guid for m in members]
        + [f"{v.name}={v.start}" for v in variables]
    )
    guid = "{" + str(uuid.UUID(hashlib.sha256(guid_source.encode()).hexdigest()[:32])) + "}"
    description = ModelDescription(
        fmiVersion="2.0",
        modelName=LOOP_NAME,
        instantiationToken=guid,
        description=(
            "PiezoController and FlexureStage in closed loop as one block (fmpy container FMU): "
            "Jacobi master at 10 kHz, the controller's commands drive the plant, the plant's "
            "sensors feed the controller; inputs are the references"
        ),
        generationTool="piezo-fmu demo.systems (fmpy.container_fmu)",
        variableNamingConvention="structured",
        defaultExperiment=DefaultExperiment(
            startTime="0", stopTime=literal(STOP_TIME), stepSize=literal(SAMPLE_PERIOD)
        ),
        coSimulation=CoSimulation(
            modelIdentifier="container_fmu", fixedInternalStepSize=SAMPLE_PERIOD
        ),
        unitDefinitions=list(units.values()),
        modelVariables=variables,
    )
    # Neither FMU has direct feedthrough, so neither has the container.
    description.outputs = [Unknown(variable=v, dependencies=[]) for v, _, _ in outputs]
    description.initialUnknowns = [
        Unknown(variable=v, dependencies=initial_dependencies(member, variable, exposed_as))
        for v, member, variable in outputs]
    return Configuration(
        parallelDoStep=False,
        modelDescription=description,
        components=[components[m.instance] for m in members],
        connections=wires,
        variableMappings=mappings,
    )


def initial_dependencies(member: Member, variable, exposed_as: dict):
    """What an output of `member` initially depends on, as the container's
    variables: the inner FMU's InitialUnknown dependencies, each mapped to
    the container variable that exposes it. None (every known) when the inner
    FMU lists none, or when one is not exposed (a wired input, whose value
    comes from the other FMU)."""
    inner = next((u for u in member.description.initialUnknowns if u.variable is variable), None)
    if inner is None or inner.dependencies is None:
        return None
    mapped = [exposed_as.get((member.instance, d.name)) for d in inner.dependencies]
    return None if any(m is None for m in mapped) else mapped


def shared_platforms(names: list[str]) -> set[str]:
    """The FMI 2.0 platforms for which every inner FMU (extracted under
    resources/<FMU>/) carries a binary: fmpy's runtime ships for linux64,
    win64 and darwin64, ours for linux64 and win64, so a container binary for a
    platform without its inner binaries would load and then fail."""
    parts = [name.split("/") for name in names if name.startswith("resources/")]
    inner = {p[1] for p in parts if len(p) >= 3}
    carried = {(p[1], p[3]) for p in parts if len(p) >= 5 and p[2] == "binaries"}
    return {platform for platform in ("linux64", "win64", "darwin64")
            if all((fmu, platform) in carried for fmu in inner)}


def write_container(members: list[Member], out: Path) -> Path:
    from fmpy.container_fmu.cli import create_container_fmu

    configuration = container_configuration(members)
    work = Path(tempfile.mkdtemp(prefix="container-"))
    try:
        raw = work / "raw.fmu"
        (work / "unzipped").mkdir()  # create_container_fmu empties it first
        create_container_fmu(configuration, work / "unzipped", raw)
        entries = []
        with zipfile.ZipFile(raw) as archive:
            platforms = shared_platforms(archive.namelist())
            if "linux64" not in platforms:
                raise SystemMismatch("the inner FMUs carry no common linux64 binary")
            for name in sorted(archive.namelist()):
                # fmpy zips its work folder while writing the zip into it: drop that.
                if name.endswith("/") or name == "Container.zip":
                    continue
                if name.startswith("binaries/") and name.split("/")[1] not in platforms:
                    continue
                entries.append((name, archive.read(name)))
        _write_zip(out, entries)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dist", type=Path, default=Path("dist"))
    args = parser.parse_args(argv)
    try:
        members = load_members(args.dist)
    except SystemMismatch as error:
        parser.exit(1, f"demo.systems: {error}\n")
    for path in (
        write_ssp(members, args.dist / f"{SYSTEM_NAME}.ssp"),
        write_container(members, args.dist / f"{LOOP_NAME}.fmu"),
    ):
        print(path)


if __name__ == "__main__":
    main()
