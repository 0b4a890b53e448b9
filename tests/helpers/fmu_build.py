"""Build the test suite's own co-simulation FMUs (FMI 2.0 and 3.0) with gcc.

The C sources are in ``tests/helpers/fmu_src``: ``rc_model.h`` is a one-node RC model
(``C dT/dt = (T_out - T)/R``, output ``q = (T_out - T)/R``), wrapped once per
FMI version. The FMI headers come with FMPy (``fmpy/c-code``). The FMI 2.0
FMU uses kelvin for its temperatures and can interpolate its input (it accepts
``fmi2SetRealInputDerivatives``); the FMI 3.0 FMU uses °C and holds its input
constant over a communication step.
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy

SRC = Path(__file__).resolve().parent / "fmu_src"
MODEL = "RCNode"

GUID2 = "{5b0c7f55-3a55-4a8e-9c1e-2f6a1f3e0c02}"
TOKEN3 = "{0d6c1b0e-7f2b-4c47-b1a4-5f3f0f6f9a03}"

_FMI2_XML = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{MODEL}" guid="{GUID2}"
    description="one-node RC model (test FMU)" variableNamingConvention="flat"
    numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{MODEL}" canHandleVariableCommunicationStepSize="true"
      canInterpolateInputs="true" maxOutputDerivativeOrder="0"/>
  <UnitDefinitions>
    <Unit name="K"><BaseUnit K="1"/></Unit>
    <Unit name="m2.K/W"><BaseUnit kg="-1" s="3" K="1"/></Unit>
    <Unit name="J/(m2.K)"><BaseUnit kg="1" s="-2" K="-1"/></Unit>
    <Unit name="W/m2"><BaseUnit kg="1" s="-3"/></Unit>
  </UnitDefinitions>
  <DefaultExperiment startTime="0" stopTime="86400" stepSize="600"/>
  <ModelVariables>
    <ScalarVariable name="R" valueReference="1" causality="parameter" variability="fixed"
        initial="exact"><Real unit="m2.K/W" start="0.5"/></ScalarVariable>
    <ScalarVariable name="C" valueReference="2" causality="parameter" variability="fixed"
        initial="exact"><Real unit="J/(m2.K)" start="20000"/></ScalarVariable>
    <ScalarVariable name="T0" valueReference="3" causality="parameter" variability="fixed"
        initial="exact"><Real unit="K" start="293.15"/></ScalarVariable>
    <ScalarVariable name="T_out" valueReference="4" causality="input"
        variability="continuous"><Real unit="K" start="293.15"/></ScalarVariable>
    <ScalarVariable name="T" valueReference="5" causality="output" variability="continuous"
        initial="calculated"><Real unit="K"/></ScalarVariable>
    <ScalarVariable name="q" valueReference="6" causality="output" variability="continuous"
        initial="calculated"><Real unit="W/m2"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs>
      <Unknown index="5" dependencies="" />
      <Unknown index="6" dependencies="4" />
    </Outputs>
    <InitialUnknowns>
      <Unknown index="5" dependencies="3" />
      <Unknown index="6" dependencies="1 3 4" />
    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""

_FMI3_XML = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="{MODEL}" instantiationToken="{TOKEN3}"
    description="one-node RC model (test FMU)" variableNamingConvention="flat">
  <CoSimulation modelIdentifier="{MODEL}" canHandleVariableCommunicationStepSize="true"/>
  <UnitDefinitions>
    <Unit name="s"><BaseUnit s="1"/></Unit>
    <Unit name="degC"><BaseUnit K="1" offset="273.15"/></Unit>
  </UnitDefinitions>
  <DefaultExperiment startTime="0" stopTime="86400" stepSize="600"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"
        unit="s"/>
    <Float64 name="R" valueReference="1" causality="parameter" variability="fixed" start="0.5"/>
    <Float64 name="C" valueReference="2" causality="parameter" variability="fixed"
        start="20000"/>
    <Float64 name="T0" valueReference="3" causality="parameter" variability="fixed"
        unit="degC" start="20"/>
    <Float64 name="T_out" valueReference="4" causality="input" variability="continuous"
        unit="degC" start="20"/>
    <Float64 name="T" valueReference="5" causality="output" variability="continuous"
        unit="degC"/>
    <Float64 name="q" valueReference="6" causality="output" variability="continuous"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="5" dependencies=""/>
    <Output valueReference="6" dependencies="4"/>
    <InitialUnknown valueReference="5" dependencies="3"/>
    <InitialUnknown valueReference="6" dependencies="1 3 4"/>
  </ModelStructure>
</fmiModelDescription>
"""


def have_compiler() -> bool:
    """Whether gcc is available to build the test FMUs."""
    return shutil.which("gcc") is not None


def build_rc_fmu(fmi_version: str, out_dir: Path) -> Path:
    """Compile the RC test model into ``out_dir/RCNode<version>.fmu`` and return its path.

    Parameters
    ----------
    fmi_version
        ``"2.0"`` or ``"3.0"``.
    out_dir
        Folder that receives the build tree and the ``.fmu`` file.
    """
    major = fmi_version.split(".")[0]
    source, xml, platform = {
        "2": (SRC / "rc_fmi2.c", _FMI2_XML, fmpy.platform),
        "3": (SRC / "rc_fmi3.c", _FMI3_XML, fmpy.platform_tuple),
    }[major]
    tree = out_dir / f"fmi{major}"
    binary_dir = tree / "binaries" / platform
    binary_dir.mkdir(parents=True, exist_ok=True)
    (tree / "modelDescription.xml").write_text(xml, encoding="utf-8")
    headers = Path(fmpy.__file__).resolve().parent / "c-code"
    subprocess.run(
        [
            "gcc",
            "-std=c99",
            "-O2",
            "-Wall",
            "-shared",
            "-fPIC",
            f"-I{headers}",
            f"-I{SRC}",
            str(source),
            "-o",
            str(binary_dir / f"{MODEL}.so"),
            "-lm",
        ],
        check=True,
        capture_output=True,
    )
    fmu = out_dir / f"{MODEL}{major}.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as archive:
        for path in sorted(tree.rglob("*")):
            if path.is_file():
                archive.write(path, path.relative_to(tree).as_posix())
    return fmu
