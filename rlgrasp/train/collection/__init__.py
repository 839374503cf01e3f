"""Collection: how the learner gets its batches from the envs.

``collect``: a worker's batch of envs (a ``SyncVectorEnv`` behind TorchRL's ``GymWrapper``), their
seeds and the errors they leave; ``collectors``: where the workers run (``collector._target_``: one
process, worker processes, Ray); ``batches``: the learner's batches and the moment the workers get new
weights; ``adr_sync``: ADR's ranges out to the workers' envs at that same moment, outcomes in from
each batch. Import the pieces from their modules; this package stays light to import.
"""
