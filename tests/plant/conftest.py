"""Fixtures of the plant tests: the FMU built once per session, and a plain stepping loop."""
from __future__ import annotations

import pytest
from fmpy import extract, read_model_description
from fmpy import calloc, free
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

import fmus
from fmus.variables import MODEL_NAME


@pytest.fixture(scope="session")
def fmu_path(tmp_path_factory):
    """The ArmExoPlant FMU, built from source into a temporary folder once per session."""
    return fmus.build_fmu(tmp_path_factory.mktemp("fmu"))


@pytest.fixture(scope="session")
def model_description(fmu_path):
    return read_model_description(fmu_path)


@pytest.fixture(scope="session")
def unzipdir(fmu_path, tmp_path_factory):
    return extract(fmu_path, unzipdir=tmp_path_factory.mktemp("unzip"))


class LogCapture:
    """fmi2 logger callback that records (status, category, message)."""

    def __init__(self):
        self.records = []

    def __call__(self, env, instance, status, category, message):
        self.records.append((status, category.decode(), message.decode()))

    def messages(self):
        return [m for _, _, m in self.records]

    def text(self):
        return "\n".join(self.messages())


@pytest.fixture
def make_slave(model_description, unzipdir):
    """Factory: an instantiated FMU2Slave plus its LogCapture (freed at teardown)."""
    created = []

    def make_with_log(name="plant"):
        log = LogCapture()
        slave = FMU2Slave(guid=model_description.guid, unzipDirectory=unzipdir,
                          modelIdentifier=MODEL_NAME, instanceName=name)
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(log)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        slave._keep_callbacks = cb  # keep the ctypes callbacks alive
        slave.instantiate(loggingOn=False, callbacks=cb)
        created.append(slave)
        return slave, log

    yield make_with_log
    for s in created:
        try:
            s.freeInstance()
        except Exception:
            pass


@pytest.fixture
def slave(make_slave):
    s, _ = make_slave()
    return s


@pytest.fixture(scope="session")
def fmu3_path(tmp_path_factory):
    """The FMI 3.0 ArmExoPlant FMU (same sources), built once per session."""
    return fmus.build_fmu(tmp_path_factory.mktemp("fmu3"), fmi_version=3)
