"""Hydra instantiates launchers only from the ``hydra_plugins`` namespace package: this is
``rlgrasp.slurm``'s launcher under the name ``configs/hydra/launcher/slurm.yaml`` gives as ``_target_``.
Without hydra-submitit-launcher (the ``slurm`` extra) it defines nothing, so that Hydra's plugin scan,
which imports every module here, stays quiet."""

try:
    from rlgrasp.slurm import CheckedSlurmLauncher as _Checked
except ImportError:  # no hydra-submitit-launcher: hydra/launcher=slurm cannot be composed anyway
    _Checked = None

if _Checked is not None:

    class CheckedSlurmLauncher(_Checked):
        __doc__ = _Checked.__doc__
