"""The closed loop: render, steer, move, judge, at a fixed control rate, from a start point on the
reference drive until the vehicle has made `length_m` of progress along it; many drives in
lockstep, their views and networks batched (on a GPU: the torch renderer and the networks there).

An intervention, as in NVIDIA's PilotNet evaluation (Bojarski et al. 2016, sec. 7.2): when the body
leaves the corridor, hits an object or drives into water, it is counted and the vehicle is put back
on the reference drive `respawn_m` past the farthest progress it made, heading along it, wheels
straight; the policy forgets its past. A drive that makes no progress ends at its time limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from offroad_path.drive.course import Course
from offroad_path.drive.policies import Frame, Policy, StereoRig, render_views_of
from offroad_path.drive.vehicle import State, Vehicle, advance
from offroad_path.viz import overlay


@dataclass(frozen=True)
class LoopSettings:
    rate_hz: float
    speed_mps: float
    length_m: float  # progress along the reference drive that ends a drive
    respawn_m: float
    timeout_factor: float  # the drive ends after this many times length_m / speed_mps
    water_intervenes: bool  # driving into water is an intervention; else only counted (water_entries)


@dataclass
class DriveLog:
    """One policy's drive from one start: what the report needs."""

    policy: str
    world: str
    start_s: float
    start: int = 0  # which of the world's starts
    seed: int = 0  # the training seed of the policy's network
    elapsed_s: float = 0.0
    distance_m: float = 0.0  # driven
    progress_m: float = 0.0  # along the reference drive, interventions' skips included: the same for every policy that finishes
    steps: int = 0
    no_path: int = 0  # steps the policy said nothing (steered straight)
    water_entries: int = 0  # times a wheel went from dry ground into water
    offsets: list[float] = field(default_factory=list)  # per step, metres from the nearest centre line
    trajectory: list[tuple[float, float]] = field(default_factory=list)  # body centre per step, NaN after an intervention
    interventions: list[tuple[float, float, str]] = field(default_factory=list)  # (x, z, why)
    frames: list[np.ndarray] = field(default_factory=list)  # the video's images, when recorded


def start_state(course: Course, s: float) -> State:
    xz, heading = course.on_reference(s)
    return State(xz=xz, heading=heading, steer=0.0)


@dataclass(frozen=True)
class Setup:
    """Where and with what a drive happens: the world's course, the vehicle, its camera, the loop's settings."""

    course: Course
    vehicle: Vehicle
    rig: StereoRig | None  # None: no policy looks (oracle, straight) and no video
    settings: LoopSettings


class Drive:
    """One drive in progress, a control step at a time: `drive` steps one, `drive_together` many in
    lockstep (their views rendered and their networks run in batches)."""

    def __init__(self, setup: Setup, policy: Policy, start_s: float, video: bool = False):
        self.setup, self.policy, self.video = setup, policy, video
        settings = setup.settings
        self.log = DriveLog(policy.name, "", start_s)
        self.end_s = min(start_s + settings.length_m, setup.course.length_m - settings.respawn_m)
        self.timeout = settings.timeout_factor * settings.length_m / settings.speed_mps
        self.state, self.s, self.farthest = start_state(setup.course, start_s), start_s, start_s
        self.wet = False
        policy.reset()

    @property
    def done(self) -> bool:
        return self.farthest >= self.end_s or self.log.elapsed_s >= self.timeout

    def frame(self) -> Frame:
        return Frame(self.state, self.s, self.setup.vehicle, self.setup.course, self.setup.rig)

    def step(self, frame: Frame, command: float | None) -> None:
        """Move by the policy's command for one control period, then judge where the vehicle is."""
        course, settings, log = self.setup.course, self.setup.settings, self.log
        dt = 1.0 / settings.rate_hz
        log.no_path += command is None
        if self.video:
            log.frames.append(_video_frame(frame, self.policy, command))
        self.state, centres = advance(self.state, self.setup.vehicle, 0.0 if command is None else command, settings.speed_mps, dt)
        log.elapsed_s += dt
        log.distance_m += settings.speed_mps * dt
        log.steps += 1
        log.offsets.append(float(course.offset(self.state.xz[None])[0]))
        log.trajectory.append((float(self.state.xz[0]), float(self.state.xz[1])))
        self.s = course.progress(self.state.xz, self.s)
        self.farthest = max(self.farthest, self.s)
        why = course.event(centres, self.state.heading)
        now_wet = course.in_water(centres, self.state.heading)
        log.water_entries += now_wet and not self.wet
        self.wet = now_wet
        if why is None and now_wet and settings.water_intervenes:
            why = "water"
        if why is not None:
            log.interventions.append((float(self.state.xz[0]), float(self.state.xz[1]), why))
            log.trajectory.append((float("nan"), float("nan")))  # the vehicle is moved: a gap in its line
            self.s = self.farthest = self.farthest + settings.respawn_m
            self.state, self.wet = start_state(course, self.s), False
            self.policy.reset()

    def finish(self) -> DriveLog:
        self.log.progress_m = min(self.farthest, self.end_s) - self.log.start_s
        return self.log


def drive(setup: Setup, policy: Policy, start_s: float, video: bool = False) -> DriveLog:
    """One drive of `policy` from arc length start_s of the reference drive."""
    return drive_together([Drive(setup, policy, start_s, video)])[0]


def drive_together(drives: list[Drive]) -> list[DriveLog]:
    """Step every drive until each ends: at each step the views every policy looks at render in one
    batch per rig (StereoRig.render_many), and the policies sharing a network run it in one batch
    (Policy.look). Each drive needs its own policy object (Policy.fresh): the policies keep state.
    The drives' logs, in order: each the same as it would be driven alone, the same views and
    network outputs given (a network's bits may depend on its batch's size)."""
    if len({id(d.policy) for d in drives}) < len(drives):
        raise ValueError("drive_together: two drives share a policy object; give each its own (Policy.fresh)")
    while active := [d for d in drives if not d.done]:
        frames = [d.frame() for d in active]
        render_views_of(frames, [d.policy.views for d in active])
        seen: list = [None] * len(active)
        for members in _sharing_a_network(active):
            outputs = active[members[0]].policy.look([frames[i] for i in members])
            for i, output in zip(members, outputs, strict=True):
                seen[i] = output
        for d, frame, output in zip(active, frames, seen, strict=True):
            d.step(frame, d.policy.act(frame, output))
    return [d.finish() for d in drives]


def _sharing_a_network(drives: list[Drive]) -> list[list[int]]:
    """Indices of the drives grouped by the kind of policy and the network it looks through (one group
    per policy without one)."""
    groups: dict[tuple, list[int]] = {}
    for i, d in enumerate(drives):
        network = d.policy.network
        groups.setdefault((type(d.policy), id(network)) if network is not None else ("alone", i), []).append(i)
    return list(groups.values())


def _video_frame(frame: Frame, policy: Policy, command: float | None) -> np.ndarray:
    """The left image (RGB) with the path the policy predicted (if it predicts one) and its command."""
    image = overlay(frame.left, policy.shown) if policy.shown is not None else frame.left.copy()
    text = "no path: straight" if command is None else f"{np.degrees(command):+.1f} deg"
    cv2.putText(image, f"{policy.name}  {text}", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return image
