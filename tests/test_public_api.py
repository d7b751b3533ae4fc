"""The public API: every name in ``dvrk_gym.__all__`` resolves, and importing the package stays light."""

import subprocess
import sys

import pytest

import dvrk_gym


@pytest.mark.parametrize("name", dvrk_gym.__all__)
def test_every_public_name_resolves(name):
    assert getattr(dvrk_gym, name) is not None
    assert name in dir(dvrk_gym)


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'NoSuchThing'"):
        dvrk_gym.NoSuchThing  # noqa: B018


def test_importing_the_package_registers_the_envs_without_loading_torch_pybullet_or_scipy():
    code = (
        "import sys, gymnasium as gym, dvrk_gym\n"
        "assert set(dvrk_gym.ENV_IDS) <= set(gym.registry), 'envs not registered'\n"
        "heavy = sorted(m for m in ('torch', 'pybullet', 'scipy', 'sklearn', 'stable_baselines3') if m in sys.modules)\n"
        "print(','.join(heavy))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == ""


def test_the_public_names_are_the_modules_own_objects():
    from dvrk_gym.calibration.policy import CalibratedPolicy
    from dvrk_gym.envs.grid_touch import GridTouchEnv

    assert dvrk_gym.CalibratedPolicy is CalibratedPolicy
    assert dvrk_gym.GridTouchEnv is GridTouchEnv
    assert dvrk_gym.make_calibrator("rbt").__class__ is dvrk_gym.RigidBodyCalibrator


def test_version_is_the_installed_distributions_and_the_cli_prints_it(capsys):
    from importlib.metadata import version

    from dvrk_gym.cli.main import main

    assert dvrk_gym.__version__ == version("dvrk-gym")
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"dvrk-gym {dvrk_gym.__version__}"


def test_every_commands_help_ends_with_examples_that_parse(capsys):
    """No command's ``--help`` showed how it is run."""
    import shlex

    from dvrk_gym.cli.main import EXAMPLES, build_parser, main

    for command, examples in EXAMPLES.items():
        with pytest.raises(SystemExit):
            main([*command.split(), "--help"])
        shown = " ".join(capsys.readouterr().out.split())
        assert f"example{'s' if len(examples) > 1 else ''}: {'; '.join(examples)}" in shown, command
        for example in examples:
            args = build_parser().parse_args(shlex.split(example)[1:])
            assert args.command == command.split()[0]
    with pytest.raises(SystemExit):
        main(["--help"])
    listed = " ".join(capsys.readouterr().out.split())
    leaves = [c for c in EXAMPLES if " " not in c] + ["baseline"]
    assert all(name in listed for name in leaves)
