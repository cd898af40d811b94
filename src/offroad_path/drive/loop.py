"""The closed loop: render, steer, move, judge, at a fixed control rate, from a start point on the
reference drive until the vehicle has made `length_m` of progress along it.

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
from offroad_path.drive.policies import Frame, Policy, StereoRig
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


def drive(setup: Setup, policy: Policy, start_s: float, video: bool = False) -> DriveLog:
    """One drive of `policy` from arc length start_s of the reference drive."""
    course, vehicle, rig, settings = setup.course, setup.vehicle, setup.rig, setup.settings
    log = DriveLog(policy.name, "", start_s)
    dt = 1.0 / settings.rate_hz
    end_s = min(start_s + settings.length_m, course.length_m - settings.respawn_m)
    timeout = settings.timeout_factor * settings.length_m / settings.speed_mps
    state, s, farthest = start_state(course, start_s), start_s, start_s
    wet = False
    policy.reset()
    while farthest < end_s and log.elapsed_s < timeout:
        frame = Frame(state, s, vehicle, course, rig)
        command = policy.steer(frame)
        log.no_path += command is None
        if video:
            log.frames.append(_video_frame(frame, policy, command))
        state, centres = advance(state, vehicle, 0.0 if command is None else command, settings.speed_mps, dt)
        log.elapsed_s += dt
        log.distance_m += settings.speed_mps * dt
        log.steps += 1
        log.offsets.append(float(course.offset(state.xz[None])[0]))
        log.trajectory.append((float(state.xz[0]), float(state.xz[1])))
        s = course.progress(state.xz, s)
        farthest = max(farthest, s)
        why = course.event(centres, state.heading)
        now_wet = course.in_water(centres, state.heading)
        log.water_entries += now_wet and not wet
        wet = now_wet
        if why is None and now_wet and settings.water_intervenes:
            why = "water"
        if why is not None:
            log.interventions.append((float(state.xz[0]), float(state.xz[1]), why))
            log.trajectory.append((float("nan"), float("nan")))  # the vehicle is moved: a gap in its line
            s = farthest = farthest + settings.respawn_m
            state, wet = start_state(course, s), False
            policy.reset()
    log.progress_m = min(farthest, end_s) - start_s
    return log


def _video_frame(frame: Frame, policy: Policy, command: float | None) -> np.ndarray:
    """The left image (RGB) with the path the policy predicted (if it predicts one) and its command."""
    image = overlay(frame.left, policy.shown) if policy.shown is not None else frame.left.copy()
    text = "no path: straight" if command is None else f"{np.degrees(command):+.1f} deg"
    cv2.putText(image, f"{policy.name}  {text}", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return image
