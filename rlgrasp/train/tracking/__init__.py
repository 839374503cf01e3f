"""Tracking: where a run's curves and counters go (named ``tracking``, not ``logging``, beside the
standard library's module).

``logger``: the console line, ``train.log`` and TensorBoard (``logger._target_``: ``ConsoleLogger``,
``TensorBoardLogger``); ``trackers``: the same plus a tracking service (``WandbLogger``,
``MlflowLogger``); ``metrics``: the loop's counters besides the losses (episodes finished, frames per
second, when an interval comes due, where the wall clock went). Import the pieces from their modules;
this package stays light to import.
"""
