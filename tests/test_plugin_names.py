"""One naming rule for the five plugin registries (ICP variants, components, ground segmenters, dataset readers,
benchmark tasks): a name is a non-empty word, a redefined class takes its name back, an other class is refused."""

from __future__ import annotations

import importlib
import sys
import textwrap

import pytest

import lidarkit.bench.tasks as bench_tasks
import lidarkit.io as lidarkit_io
import lidarkit.registration.components  # noqa: F401 - registers the built-in components
import lidarkit.registration.components.registry as component_registry
import lidarkit.registration.ground  # noqa: F401 - registers the built-in ground segmenters
import lidarkit.registration.ground.base as ground_base
import lidarkit.registration.registry as icp_registry
from lidarkit.bench.tasks import Task, available_tasks, get_task, register_task
from lidarkit.errors import ConfigError
from lidarkit.io import available_datasets, get_reader, register_dataset
from lidarkit.registration import Registration, RegistrationConfig, available_icp, get_icp_class, register_icp
from lidarkit.registration.components import Kernel, available_components, get_component_class, register_component
from lidarkit.registration.ground.base import (
    GroundSegmenter,
    available_ground_segmenters,
    get_ground_segmenter_class,
    register_ground_segmenter,
)


@pytest.fixture
def registries(monkeypatch):
    """Each registry replaced by a copy, so that what a test registers is gone after it (entry points loaded first)."""
    available_icp(), available_components()
    monkeypatch.setattr(icp_registry, "_VARIANTS", dict(icp_registry._VARIANTS))
    monkeypatch.setattr(component_registry, "_COMPONENTS", {k: dict(v) for k, v in component_registry._COMPONENTS.items()})
    monkeypatch.setattr(ground_base, "_REGISTRY", dict(ground_base._REGISTRY))
    monkeypatch.setattr(bench_tasks, "_REGISTERED", dict(bench_tasks._REGISTERED))
    monkeypatch.setattr(bench_tasks, "_INSTANCES", dict(bench_tasks._INSTANCES))
    monkeypatch.setattr(lidarkit_io, "_REGISTERED", dict(lidarkit_io._REGISTERED))


def _icp_class(label):
    return type(label, (Registration,), {"Config": RegistrationConfig})


# registry: (register(name), a class it takes, the names it lists, its call's source for a name, the noun)
REGISTRIES = {
    "icp": (register_icp, _icp_class, available_icp, "register_icp", "a variant name"),
    "component": (lambda name: register_component("kernel", name), lambda label: type(label, (Kernel,), {}),
                  lambda: available_components("kernel"), "register_component('kernel')", "a component name"),
    "ground": (register_ground_segmenter, lambda label: type(label, (GroundSegmenter,), {}), available_ground_segmenters,
               "register_ground_segmenter", "a ground segmenter name"),
    "task": (register_task, lambda label: type(label, (Task,), {}), available_tasks, "register_task", "a task name"),
    "dataset": (register_dataset, lambda label: type(label, (), {}), available_datasets, "register_dataset", "a dataset kind"),
}


@pytest.mark.parametrize("registry", list(REGISTRIES))
def test_every_registry_refuses_a_name_that_is_no_word(registries, registry):
    """None, "" or a name with spaces was registered by four of the registries (register_icp let "a b" through); None
    then broke the registry's listing and every "unknown name" message with a TypeError from sorted()."""
    register, make_class, available, source, noun = REGISTRIES[registry]
    for bad in (None, "", " x", "a b", "x\t", 5):
        with pytest.raises(ConfigError) as refused:
            register(bad)(make_class("Named"))
        assert str(refused.value) == f"{source}: {noun} must be a non-empty word without spaces, got {bad!r}"
    assert all(isinstance(name, str) for name in available())


TAKEN = {  # registry: (a built-in name, the class holding it as the message names it, how the registry finds it)
    "icp": ("vanilla", "lidarkit.registration.vanilla.VanillaICP", get_icp_class),
    "component": ("huber", "lidarkit.registration.components.kernels.HuberKernel",
                  lambda name: get_component_class("kernel", name)),
    "ground": ("height", "lidarkit.registration.ground.height.HeightSegmenter", get_ground_segmenter_class),
    "task": ("odometry", "the built-in lidarkit.bench.tasks.odometry.OdometryTask", lambda name: type(get_task(name))),
    "dataset": ("kitti", "the built-in lidarkit.io.kitti.KittiOdometry", get_reader),
}


@pytest.mark.parametrize("registry", list(TAKEN))
def test_an_other_class_under_a_taken_name_is_refused_naming_the_holder(registries, registry):
    """register_task("odometry") and register_dataset("kitti") replaced the built-in without a word, as did any task or
    reader registered twice; the ground registry named the holder without its module."""
    register, make_class, _, _, _ = REGISTRIES[registry]
    builtin, holder, lookup = TAKEN[registry]
    held_by = lookup(builtin)
    source = f"register_component('kernel', {builtin!r})" if registry == "component" else f"{register.__name__}({builtin!r})"
    with pytest.raises(ConfigError) as refused:
        register(builtin)(make_class("Impostor"))
    assert str(refused.value) == f"{source}: name already taken by {holder}; register yours under another name"
    assert lookup(builtin) is held_by and lookup(builtin).__name__ != "Impostor"

    first = register("plugin_name_test")(make_class("First"))
    with pytest.raises(ConfigError, match=r"name already taken by \S+\.First; register yours under another name$"):
        register("plugin_name_test")(make_class("Second"))
    assert lookup("plugin_name_test") is first


CELL = textwrap.dedent("""
    from lidarkit.registration import Registration, RegistrationConfig, register_icp

    @register_icp("notebook_cell_icp")
    class MyICP(Registration):
        Config = RegistrationConfig
""")


def test_a_notebook_cell_run_again_registers_its_variant_again(registries):
    """Running a cell that defines and registers a variant a second time failed "name already taken by
    __main__.MyICP": the same class defined again (same module and qualified name) takes its name back."""
    cell: dict = {"__name__": "__main__"}
    exec(compile(CELL, "<cell 1>", "exec"), cell)
    first = cell["MyICP"]
    exec(compile(CELL, "<cell 1, run again>", "exec"), cell)
    assert cell["MyICP"] is not first
    assert get_icp_class("notebook_cell_icp") is cell["MyICP"]
    with pytest.raises(ConfigError, match=r"register_icp\('notebook_cell_icp'\): name already taken by __main__\.MyICP;"):
        exec(compile(CELL.replace("class MyICP", "class YourICP"), "<cell 2>", "exec"), {"__name__": "__main__"})


PLUGIN_MODULE = textwrap.dedent("""
    from lidarkit.bench.tasks import Task, register_task
    from lidarkit.io import register_dataset
    from lidarkit.registration import Registration, RegistrationConfig, register_icp
    from lidarkit.registration.components import Kernel, register_component
    from lidarkit.registration.ground.base import GroundSegmenter, register_ground_segmenter

    @register_icp("reloaded_icp")
    class ReloadedICP(Registration):
        Config = RegistrationConfig

    @register_component("kernel", "reloaded_kernel")
    class ReloadedKernel(Kernel):
        pass

    @register_ground_segmenter("reloaded_ground")
    class ReloadedGround(GroundSegmenter):
        pass

    @register_task("reloaded_task")
    class ReloadedTask(Task):
        pass

    @register_dataset("reloaded_reader")
    class ReloadedReader:
        def __init__(self, path):
            self.path = path
""")


def test_a_reloaded_plugin_module_registers_its_classes_again(registries, tmp_path, monkeypatch):
    """importlib.reload of a module registering an ICP variant, a component or a ground segmenter failed "name already
    taken" by its own earlier class; every registry now holds the reloaded classes."""
    module_name = "lidarkit_reloaded_plugin_test"
    (tmp_path / f"{module_name}.py").write_text(PLUGIN_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module(module_name)
    monkeypatch.setitem(sys.modules, module_name, module)  # (dropped again after the test)
    before = {name: getattr(module, name) for name in dir(module) if name.startswith("Reloaded")}
    module = importlib.reload(module)
    found = {
        "ReloadedICP": get_icp_class("reloaded_icp"),
        "ReloadedKernel": get_component_class("kernel", "reloaded_kernel"),
        "ReloadedGround": get_ground_segmenter_class("reloaded_ground"),
        "ReloadedTask": type(get_task("reloaded_task")),
        "ReloadedReader": get_reader("reloaded_reader"),
    }
    assert sorted(found) == sorted(before)
    for name, cls in found.items():
        assert cls is getattr(module, name) and cls is not before[name], name
    assert found["ReloadedTask"].name == "reloaded_task" and found["ReloadedICP"].name == "reloaded_icp"
