"""Soft actor-critic on the training core (``algo=sac``), with demonstrations in the replay (RLPD).

TorchRL provides the replay buffers and the actor's TanhNormal policy. The losses (twin or ensemble
critics, the entropy temperature learned towards a target entropy, target critics and their soft
update) are ``rlgrasp.algos.sac.losses``' on the batched critics of ``rlgrasp.algos.sac.critics``:
TorchRL's ``SACLoss`` formulas without its per-call parameter swaps, which cost a CPU learner about
as much as the arithmetic (why, there). This module adds what rlgrasp needs around them: the
update-to-data ratio kept across batches of any size, symmetric sampling of demonstrations beside
online data (Ball et al. 2023: each minibatch half and half), critics that read the actor's running
observation normalizer, and a replay buffer that a resumed run continues with.

With a camera (``cameras=wrist_depth`` and the like) it learns from pixels the DrQ-v2 way (Yarats et
al. 2021): the camera actor's image encoders are trained by the critics' loss alone, the actor gets
their features detached, each replayed image is shifted by a few pixels (random shift), and the
critics may also read the privileged state no robot senses (asymmetric actor-critic; they are not
deployed). ``algo.encoder.trained_by`` may give the encoders the actor's loss instead, or both.
Replayed images are kept compact: RGB as uint8, depth as float16.

The actor is the parts' TanhNormal policy, so evaluation, export, enjoy and sweeps take a SAC
checkpoint as they take a PPO one. The workers keep collecting the next batch while the learner
updates on this one (``collector.overlap``): off-policy, one batch of lag costs nothing.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp.algos.sac.critics import CriticEnsemble
from rlgrasp.algos.sac.her import EPISODE_KEY, Hindsight, goal_layout
from rlgrasp.algos.sac.losses import SoftActorCriticLoss
from rlgrasp.algos.sac.replay_files import ReplayFiles
from rlgrasp.config import ConfigError
from rlgrasp.demos.bc import mse_bc_loss
from rlgrasp.demos.dataset import demo_transitions, demos_for
from rlgrasp.envs.cameras import GROUND_MASK_KEY
from rlgrasp.models.cnn import head_actor, image_specs, vision_net
from rlgrasp.models.mlp import OBS_KEY
from rlgrasp.models.spec import PRIVILEGED_KEY
from rlgrasp.train.algorithm import Algorithm, finite_or_raise
from rlgrasp.train.tracking.logger import log
from rlgrasp.vision.augment import augment_images
from rlgrasp.vision.auxiliary import ObjectFromImages
from rlgrasp.vision.object_map import ObjectMap

#: The entries a transition keeps in the replay buffer (the collector's batch has more).
TRANSITION_KEYS = (
    OBS_KEY,
    "action",
    ("next", OBS_KEY),
    ("next", "reward"),
    ("next", "done"),
    ("next", "terminated"),
)
#: Where a camera learner puts the images' features in a minibatch: the critics read this key, the
#: actor head the second (the same features, each detached or not as ``algo.encoder.trained_by`` says).
FEATURES_KEY = "image_features"
ACTOR_FEATURES_KEY = "actor_image_features"
#: What a replayed image is stored as: RGB arrives as uint8; depth (metres) loses nothing a 64-pixel
#: policy reads at half precision.
STORED_DTYPES = {"rgb": torch.uint8, "depth": torch.float16, GROUND_MASK_KEY: torch.uint8}


class SAC(Algorithm):
    """SAC, optionally with demonstrations sampled beside online data (RLPD). A subclass changes the
    loss (``_make_loss``) and what a critic outputs (``critic_outputs``): TQC (``rlgrasp.algos.tqc``)."""

    name = "sac"

    def __init__(self, cfg: Any, parts: Any, device: torch.device) -> None:
        super().__init__(cfg, parts, device)
        a = cfg.algo
        self.norm = parts.norm
        self.images = image_specs(parts.spec)  # key -> shape; empty: a state policy
        privileged = a.critic.privileged or a.terms.aux.coeff > 0 or a.terms.object_map.coeff > 0
        self.transition_keys = _transition_keys(self.images, privileged, a.augment.ground_swap > 0)
        self.her = self._her()
        if self.her is not None:  # each transition's episode, which relabelling draws goals from
            self.transition_keys = (*self.transition_keys, EPISODE_KEY)
        self.aux = self._aux()
        self.object_map = self._object_map()
        act_dim = len(parts.spec["action_low"])
        self.loss = self._make_loss(act_dim)
        self.optimizers = self._optimizers(a.optim)
        if self.images:
            _check_replay_memory(a.replay, parts.spec, self.transition_keys)
        self.demos = self._demos() if a.get("demos") else None
        bc_on = self.demos is not None and a.terms.imitation.coeff > 0
        self.bc = mse_bc_loss(self._loss_actor()) if bc_on else None
        online = a.optim.batch_size - (self.demos.batch_size if self.demos is not None else 0)
        self.replay = _buffer(a.replay.buffer_frames, online, device)
        self.owed = 0.0  # gradient steps due but not yet taken (the ratio is kept across batches)
        # Transitions ever put in the buffer (its ring's write position is this modulo its size),
        # and of them, those already in the run's replay files.
        self.stored = 0
        self.saved = 0
        self.replay_sequence = 0  # the newest replay file's number: the checkpoint names it

    def _make_loss(self, act_dim: int) -> SoftActorCriticLoss:
        """SAC's losses on the actor and the critics (``rlgrasp.algos.sac.losses``). A subclass may
        return another loss of its interface (``critic_loss``, ``actor_loss``, ``alpha_loss``,
        ``soft_update``): TQC's."""
        loss = self.cfg.algo.loss
        critics, keys = self._critics(act_dim)
        return SoftActorCriticLoss(
            self._loss_actor(),
            critics,
            keys,
            gamma=loss.gamma,
            alpha_init=loss.alpha_init,
            target_entropy=self._target_entropy(act_dim),
        )

    def _target_entropy(self, act_dim: int) -> float:
        target = self.cfg.algo.loss.target_entropy
        return float(target) if target is not None else -float(act_dim)

    def _optimizers(self, optim: Any) -> dict[str, torch.optim.Optimizer]:
        """Adam for the actor, the critics and the temperature; with a camera, for the encoders too,
        which learn from the loss ``algo.encoder.trained_by`` names (at the critics' rate)."""
        optimizers = {
            "actor": _adam(_trainable(self.loss.actor), optim.actor_lr),
            "critic": _adam(_trainable(self.loss.critics), optim.critic_lr),
            "alpha": _adam([self.loss.log_alpha], optim.alpha_lr),
        }
        if self.images:
            params = [*self._encoder().parameters(), *self._aux_parameters()]
            optimizers["encoder"] = _adam(params, optim.critic_lr)
        return optimizers

    def _her(self) -> Hindsight | None:
        """With ``algo.her.enabled``: hindsight relabelling of the online replay (rlgrasp.algos.sac.her),
        its goals' place in the observation read from the env (a task without goals refused here)."""
        her = self.cfg.algo.get("her")
        if her is None or not her.enabled:
            return None
        size = self.cfg.algo.replay.buffer_frames
        return Hindsight(her, goal_layout(self.parts.make_env), size, self.device)

    def _aux(self) -> ObjectFromImages | None:
        """With ``algo.terms.aux.coeff`` > 0: a linear head on the image features regressed onto parts
        of the privileged state (rlgrasp.vision.auxiliary), so that the encoders learn where the object
        is even when the critics read it from the privileged state and need little from the images."""
        aux = self.cfg.algo.terms.aux
        if aux.coeff <= 0:
            return None
        if not self.images:
            raise ConfigError(
                f"algo.terms.aux.coeff={aux.coeff}: the auxiliary task reads image features; needs a camera "
                "(e.g. cameras=wrist_depth)"
            )
        head = ObjectFromImages(self._encoder(), self.parts.spec["privileged_parts"], aux.parts, tap=False)
        return head.to(self.device)

    def _object_map(self) -> ObjectMap | None:
        """With ``algo.terms.object_map.coeff`` > 0: the encoders' first keypoint trained onto the
        object's pixels (rlgrasp.vision.object_map)."""
        if self.cfg.algo.terms.object_map.coeff <= 0:
            return None
        if not self.images:
            raise ConfigError("algo.terms.object_map.coeff: trains an image encoder; needs a camera")
        spec = self.parts.spec
        return ObjectMap(self._encoder(), spec["privileged_parts"], self.images, self.cfg.model)

    def _aux_parameters(self) -> list[torch.nn.Parameter]:
        return list(self.aux.parameters()) if self.aux is not None else []

    def _encoder(self) -> nn.Module:
        return vision_net(self.actor).encoders

    def _loss_actor(self) -> nn.Module:
        """What the loss trains as the actor: the whole actor on the state; with a camera, the actor
        after its encoders, reading their features (``_inputs``)."""
        return head_actor(self.actor, ACTOR_FEATURES_KEY) if self.images else self.actor

    def _critics(self, act_dim: int) -> tuple[CriticEnsemble, list[Any]]:
        """The critics (``algo.loss.num_critics`` of them, ``critic_outputs`` values each) and the
        minibatch entries they read before the action: the state; with a camera, the state (the
        privileged one with ``algo.critic.privileged``) and the images' features."""
        a, spec = self.cfg.algo, self.parts.spec
        keys, norm, dim = [OBS_KEY], self.norm, spec["obs_dim"]
        if self.images:
            features = sum(e.project[0].out_features for e in self._encoder().values())
            if a.critic.privileged:
                keys, norm, dim = [PRIVILEGED_KEY], self.parts.norms[PRIVILEGED_KEY], spec["privileged_dim"]
            keys, dim = [*keys, FEATURES_KEY], dim + features
        c = a.critic
        critics = CriticEnsemble(
            norm,
            a.loss.num_critics,
            dim + act_dim,
            list(c.hidden_sizes),
            c.activation,
            c.layer_norm,
            self.critic_outputs,
        )
        return critics.to(self.device), keys

    @property
    def critic_outputs(self) -> int:
        """What each critic outputs per state and action: one Q-value (TQC: its quantiles)."""
        return 1

    def _demos(self) -> TensorDictReplayBuffer:
        """The demonstrations as transitions in a buffer of their own (read, and refused, before any
        worker starts)."""
        a = self.cfg.algo
        frames = demo_transitions(demos_for(a.demos, self.parts.make_env, self.cfg.env), self.cfg.env)
        if GROUND_MASK_KEY in self.transition_keys and GROUND_MASK_KEY not in frames.keys():
            raise ConfigError(
                f"algo.demos={a.demos}: recorded without the camera's ground mask, which "
                f"algo.augment.ground_swap={a.augment.ground_swap} reads; record them with "
                "+env.camera.ground_mask=true"
            )
        batch = a.optim.batch_size
        demos = _buffer(
            frames.numel(), min(batch - 1, max(1, round(batch * a.replay.demo_ratio))), self.device
        )
        # Not relabelled, so without the episode number HER keeps for the online rows.
        keys = [k for k in self.transition_keys if k != EPISODE_KEY]
        demos.extend(_compact(frames.select(*keys)).to(self.device))
        return demos

    def start(self, log_scalars: Any) -> None:
        """With demonstrations and ``algo.pretrain.epochs``: behaviour cloning on them before the first
        frame, so that the workers' first episodes explore around the expert (the imitation term
        then keeps the actor there while the critics learn). The observation normalizer starts from
        the demonstrations' statistics, which online batches then continue, as PPO's pre-training."""
        pretrain = self.cfg.algo.pretrain
        if self.demos is None or not pretrain.epochs:
            return
        demos = self.demos[:]
        self.norm.update(demos[OBS_KEY].float())
        if PRIVILEGED_KEY in self.transition_keys:
            self.parts.norms[PRIVILEGED_KEY].update(demos[PRIVILEGED_KEY].float())
        bc = self.bc or mse_bc_loss(self._loss_actor())
        optimizer = torch.optim.Adam(self.actor.parameters(), lr=pretrain.lr)
        steps = pretrain.epochs * -(-len(demos) // self.demos.batch_size)
        losses = []
        for _ in range(steps):
            with_features, _ = self._inputs(self.demos.sample())  # a camera's encoders learn too
            with set_exploration_type(ExplorationType.DETERMINISTIC):
                loss = bc(with_features)["loss_bc"]
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            losses.append(float(loss.detach()))
        log_scalars(
            {
                "pretrain/bc_loss_first": losses[0],
                "pretrain/bc_loss_last": losses[-1],
                "pretrain/steps": float(steps),
            },
            0,
        )

    def update(self, batch: TensorDictBase, frames: int) -> dict[str, float]:
        """Store the batch, then take ``utd_ratio`` gradient steps per new frame once the buffer
        holds ``learning_starts`` frames (the steps not taken before are not made up)."""
        optim = self.cfg.algo.optim
        t0 = time.perf_counter()
        flat = self.remember(batch)
        if len(self.replay) < self.cfg.algo.replay.learning_starts:
            return {"charts/replay_frames": float(len(self.replay))}
        self.owed += optim.utd_ratio * flat.numel()
        steps = int(self.owed)
        self.owed -= steps
        sums: dict[str, float] = {}
        for _ in range(steps):
            for key, value in self._step().items():
                sums[key] = sums.get(key, 0.0) + value
        metrics = {k: v / max(steps, 1) for k, v in sums.items()}
        metrics["charts/replay_frames"] = float(len(self.replay))
        metrics["charts/gradient_steps"] = float(steps)
        metrics["time/train_s"] = time.perf_counter() - t0
        return metrics

    def remember(self, batch: TensorDictBase) -> TensorDictBase:
        """Store a collector batch ``[envs, steps]`` (with ``algo.her``, each transition labelled with
        its episode first); returns it flattened."""
        flat = batch.reshape(-1)
        if self.her is not None:
            flat.set(EPISODE_KEY, self.her.episodes.label(batch).to(flat.device))
        self.store(flat)
        return flat

    def store(self, flat: TensorDictBase) -> None:
        """Add a flat batch of transitions to the replay buffer (images in their stored dtype) and
        update the normalizers (and the auxiliary head's target statistics) from it."""
        self.norm.update(flat[OBS_KEY])
        if PRIVILEGED_KEY in self.transition_keys:
            self.parts.norms[PRIVILEGED_KEY].update(flat[PRIVILEGED_KEY])
        if self.aux is not None:
            self.aux.update(flat)
        self._extend(_compact(flat.select(*self.transition_keys)))

    def _extend(self, transitions: TensorDictBase) -> None:
        self.replay.extend(transitions.to(self.device))
        if self.her is not None:  # the rows the ring wrote (as _newest reads them back)
            rows = (
                torch.arange(self.stored, self.stored + transitions.shape[0])
                % self.cfg.algo.replay.buffer_frames
            )
            self.her.written(rows, transitions)
        self.stored += transitions.shape[0]

    def _newest(self, count: int) -> TensorDictBase:
        """The ``count`` transitions stored last, oldest first."""
        size = self.cfg.algo.replay.buffer_frames
        return self.replay[torch.arange(self.stored - count, self.stored) % size]

    def _sample(self) -> TensorDictBase:
        """A minibatch: online transitions (with ``algo.her``, some relabelled), and with demonstrations
        ``demo_ratio`` of it theirs (not relabelled: an expert's episodes reach their own goals)."""
        online = self.replay.sample()
        if self.her is not None:
            online = self.her.relabel(online)[0].exclude(EPISODE_KEY)
        if self.demos is None:
            return online
        return torch.cat([online, self.demos.sample()])

    def _step(self) -> dict[str, float]:
        """One gradient step of the critics (and a camera's encoders), the actor (every
        ``actor_every`` steps) and the temperature, then the target critics' soft update."""
        a = self.cfg.algo
        for_critic, for_actor = self._inputs(self._sample())
        loss_qvalue = self.loss.critic_loss(for_critic)
        loss_actor, log_prob = self.loss.actor_loss(for_actor)
        loss_bc = self._bc_loss(for_critic)
        loss_actor = loss_actor + a.terms.imitation.coeff * loss_bc if loss_bc is not None else loss_actor
        loss_alpha = self.loss.alpha_loss(log_prob)
        loss_aux = None
        if self.aux is not None:  # on features that carry gradient: it trains the encoders too
            loss_aux = self.aux.loss_of(for_critic[ACTOR_FEATURES_KEY], for_critic)
        loss_map = self.object_map.loss(for_critic) if self.object_map is not None else None
        self.updates += 1
        actor_step = self.updates % a.optim.actor_every == 0
        total = loss_qvalue + (loss_actor + loss_alpha if actor_step else 0.0)
        if loss_aux is not None:
            total = total + a.terms.aux.coeff * loss_aux
        if loss_map is not None:
            total = total + a.terms.object_map.coeff * loss_map
        finite_or_raise(total.detach(), "SAC loss")
        for opt in self.optimizers.values():
            opt.zero_grad(set_to_none=True)
        total.backward()
        self.optimizers["critic"].step()
        if "encoder" in self.optimizers:
            self.optimizers["encoder"].step()
        if actor_step:
            self.optimizers["actor"].step()
            self.optimizers["alpha"].step()
        self.loss.soft_update(a.loss.tau)
        metrics = {
            "loss_qvalue": float(loss_qvalue.detach()),
            "loss_actor": float(loss_actor.detach()),
            "alpha": float(self.loss.log_alpha.detach().exp()),
            "entropy": float(-log_prob.mean()),
        }
        if loss_bc is not None:
            metrics["loss_bc"] = float(loss_bc.detach())
        if loss_aux is not None:
            metrics["loss_aux"] = float(loss_aux.detach())
        if loss_map is not None:
            metrics["loss_object_map"] = float(loss_map.detach())
        if self.her is not None:
            metrics["her/relabelled_reward"] = self.her.paid
        return metrics

    def _bc_loss(self, for_critic: TensorDictBase) -> torch.Tensor | None:
        """With ``algo.terms.imitation.coeff`` > 0: the squared distance between the actor's deterministic
        action and the demonstrated one, on the demonstrations' rows of the minibatch (the last ones,
        ``_sample``). It holds the actor near the expert while the critics are still wrong, which RLPD
        alone leaves to the critics (Nair et al. 2018 add the same term to DDPG). With a camera it reads
        the features the critics' loss trains, not detached: the demonstrated actions are a supervised
        signal for the encoders, as for a DAgger student's (on the cube this did not make the camera
        learner faster: docs/algorithms.md)."""
        if self.bc is None:
            return None
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            return self.bc(for_critic[-self.demos.batch_size :])["loss_bc"]

    def _inputs(self, sample: TensorDictBase) -> tuple[TensorDictBase, TensorDictBase]:
        """The minibatch as the critics' loss reads it and as the actor's does. With a camera: each
        image augmented at random (``_augmented``; the next image its own draw), encoded once; the next
        images are encoded without gradient (the target). ``algo.encoder.trained_by`` says which loss
        the features carry gradient in: the critics' (their key in the critics' minibatch), the
        actor's (the actor's key in the actor's minibatch; its critics always read them detached, so
        the actor cannot move the features to please the critics), or both. Behaviour cloning reads
        the critics' minibatch with the features attached: demonstrated actions train the encoders."""
        if not self.images:
            return sample, sample
        trained_by = self.cfg.algo.encoder.trained_by
        net = vision_net(self.actor)

        def encode(td: TensorDictBase, target: bool) -> torch.Tensor:
            mask = td.get(GROUND_MASK_KEY, None)
            return net.encode(*(self._augmented(td[k], k, target, mask) for k in self.images))

        features = encode(sample, target=False)
        if self.object_map is not None:
            self.object_map.keep()  # the maps of these images, before the next images' pass
        with torch.no_grad():
            next_features = encode(sample["next"], target=True)
        for_critic = sample.clone(False)
        for_critic[FEATURES_KEY] = features if trained_by != "actor" else features.detach()
        for_critic[ACTOR_FEATURES_KEY] = features
        for_critic["next", FEATURES_KEY] = next_features
        for_critic["next", ACTOR_FEATURES_KEY] = next_features
        for_actor = for_critic.clone(False)
        for_actor[FEATURES_KEY] = features.detach()
        for_actor[ACTOR_FEATURES_KEY] = features if trained_by != "critic" else features.detach()
        return for_critic, for_actor

    def _augmented(
        self, images: torch.Tensor, key: str, target: bool, ground_mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Replayed images as the encoders learn from them: RGB ones with their ground swapped
        (``algo.augment.ground_swap``, where ``ground_mask`` says) and overlaid with patterns
        (``algo.augment.overlay``), neither for the ``target``'s next images, whose values the losses
        regress onto; each shifted (``algo.augment.shift``) and, with ``algo.augment.kind=colour``,
        recoloured; each image its own draw."""
        aug = self.cfg.algo.augment
        overlay_strength, ground_swap = (0.0, 0.0) if target else (aug.overlay, aug.ground_swap)
        return augment_images(
            images, key, aug.kind, aug.grey, aug.shift, overlay_strength, ground_mask, ground_swap
        )

    def trained_parameters(self) -> list[torch.nn.Parameter]:
        critics = _trainable(self.loss.critics)
        return [*self.actor.parameters(), *critics, *self._aux_parameters()]

    def state_dict(self) -> dict[str, Any]:
        """The critics, their targets, the temperature and the optimizers (the replay buffer goes
        to its own file, ``save_extra``)."""
        return {
            "loss": self.loss.state_dict(),
            "optimizers": {k: o.state_dict() for k, o in self.optimizers.items()},
            "owed": self.owed,
            "replay_sequence": self.replay_sequence,
            **({"aux": self.aux.state_dict()} if self.aux is not None else {}),
        }

    def load_state_dict(self, saved: dict[str, Any]) -> None:
        """A checkpoint's learner state; one written with TorchRL's ``SACLoss`` (``TQCLoss``) too: its
        critics are renamed onto ours (``SoftActorCriticLoss.load_state_dict``), and the optimizers'
        state, which follows the parameters' order, loads as it is."""
        self.loss.load_state_dict(saved["loss"])
        for key, opt in self.optimizers.items():
            opt.load_state_dict(saved["optimizers"][key])
        self.owed = saved["owed"]
        if self.aux is not None and "aux" in saved:
            self.aux.load_state_dict(saved["aux"])
        # Checkpoints written before the number was saved read every file there is.
        self.load_replay(Path(self.cfg.paths.output_dir), saved.get("replay_sequence"))

    def save_extra(self, run_dir: Any) -> None:
        """The transitions stored since the last checkpoint, one more file beside the checkpoints
        (``rlgrasp.algos.sac.replay_files``), written before the checkpoint that names it. The files
        older than the last checkpoint's buffer held are removed first: that checkpoint, the one a
        run killed before the next is written resumes from, keeps all of its own. A file that cannot
        be written (a full disk) does not cost the checkpoint too: it then names the files before,
        and a resume lacks this interval's transitions, as the log says."""
        if not self.cfg.algo.replay.save or len(self.replay) == 0:
            return
        files = ReplayFiles(run_dir)
        try:
            if self.saved == 0:  # nothing of this run's on disk yet: whatever is there is another run's
                files.clear()
            files.prune(self.cfg.algo.replay.buffer_frames)
            new = min(self.stored - self.saved, len(self.replay))
            if new > 0:
                self.replay_sequence = files.write(self._newest(new))
                self.saved = self.stored
        except OSError as exc:
            log.warning("replay file not written (%s): the checkpoint goes without them", exc)

    def load_replay(self, run_dir: Path, sequence: int | None = None) -> None:
        """Continue with the run's replay buffer up to the file numbered ``sequence`` (the one the
        checkpoint names; None: every file), or say that the run starts with an empty one."""
        files = ReplayFiles(run_dir)
        if sequence is not None:
            for path in files.discard_after(sequence):
                log.warning(
                    "removed %s: not part of the checkpoint resumed (written after it, or cut short)", path
                )
        if not files.exist():
            log.warning(
                "no replay files in %s: the resumed run starts with an empty replay buffer", files.folder
            )
            return
        for transitions in files.read():
            self._extend(transitions)
        self.saved = self.stored
        chunks = files.chunks()
        self.replay_sequence = chunks[-1][0] if chunks else 0
        log.info("replay buffer: %s frames from %s", f"{len(self.replay):,}", files.folder)


def _transition_keys(images: dict[str, Any], privileged: bool, ground: bool = False) -> tuple[Any, ...]:
    """What a transition keeps: the state's, and a camera's images (and, for a privileged critic,
    the privileged state), each with its next; with ``ground``, the images' ground mask (not the
    next one: the targets' images keep their ground)."""
    extra = [*images, *([PRIVILEGED_KEY] if images and privileged else [])]
    mask = [GROUND_MASK_KEY] if images and ground else []
    return (*TRANSITION_KEYS, *extra, *mask, *(("next", k) for k in extra))


def _compact(transitions: TensorDictBase) -> TensorDictBase:
    """Images in their stored dtype (``STORED_DTYPES``)."""
    for key in transitions.keys(True, True):
        name = key[-1] if isinstance(key, tuple) else key
        if name in STORED_DTYPES:
            transitions[key] = transitions[key].to(STORED_DTYPES[name])
    return transitions


def replay_bytes_per_frame(spec: dict[str, Any], keys: tuple[Any, ...]) -> int:
    """What one transition takes in the replay buffer (images in their stored dtype, the rest float32)."""
    size = 0
    for key in keys:
        name = key[-1] if isinstance(key, tuple) else key
        if name in spec.get("images", {}):
            numel = int(torch.Size(spec["images"][name]).numel())
            size += numel * STORED_DTYPES[name].itemsize
        elif name == GROUND_MASK_KEY:  # a byte a pixel of each stacked RGB frame
            size += int(torch.Size(spec["images"]["rgb"]).numel()) // 3
        else:
            dims = {
                OBS_KEY: spec["obs_dim"],
                PRIVILEGED_KEY: spec.get("privileged_dim", 0),
                "action": len(spec["action_low"]),
            }
            size += 4 * dims.get(name, 1)
    return size


def _check_replay_memory(replay_cfg: Any, spec: dict[str, Any], keys: tuple[Any, ...]) -> None:
    """Refuse, before any worker starts, an image replay buffer larger than the memory available."""
    need = replay_cfg.buffer_frames * replay_bytes_per_frame(spec, keys)
    available = _available_memory()
    if available is not None and need > 0.8 * available:
        raise ConfigError(
            f"algo.replay.buffer_frames={replay_cfg.buffer_frames:,}: the image replay buffer would take "
            f"{need / 2**30:.1f} GiB and {available / 2**30:.1f} GiB are available; lower "
            "algo.replay.buffer_frames"
        )


def _available_memory() -> int | None:
    """The memory available for new allocations (Linux's ``MemAvailable``), or None where unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _trainable(module: nn.Module) -> list[torch.nn.Parameter]:
    """The parameters of ``module`` that take gradients (not the normalizer's statistics), in the
    order TorchRL's loss listed them (the optimizers' saved state follows it)."""
    return [p for p in module.parameters() if p.requires_grad]


def _adam(params: list[torch.nn.Parameter], lr: float) -> torch.optim.Adam:
    """Adam as one fused kernel over all its parameters (CPU and CUDA): the per-parameter loop of the
    default implementation took about a tenth of a CPU gradient step at rlgrasp's sizes. A checkpoint
    written before keeps its unfused setting when loaded (``Optimizer.load_state_dict`` restores it):
    the same update, a little slower."""
    return torch.optim.Adam(params, lr=lr, fused=True)


def _buffer(frames: int, batch_size: int, device: torch.device) -> TensorDictReplayBuffer:
    return TensorDictReplayBuffer(storage=LazyTensorStorage(frames, device=device), batch_size=batch_size)
