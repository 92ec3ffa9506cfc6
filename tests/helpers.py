"""Plain helpers several test modules share: paths, analytic passes and parts built on call,
an independent FCL distance, tiny training configs, pickle payloads, property-test strategies,
the export suites' snake trajectory. Fixtures (built once per session) live in conftest.py."""

from __future__ import annotations

import errno
import math
import multiprocessing
import os
import pickle
import socket
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import fcl
import numpy as np
import trimesh
from click.testing import Result
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.core.context import PlanContext
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging import Metrics, evaluate
from scanplan.planning.pass_path import ViewRaster, plan_path
from scanplan.planning.swaths import Swath, plan_swaths, swath_record
from scanplan.rl.planners import make_planner
from scanplan.robot.export import ExportOptions, parse_pose_arg
from scanplan.world.part import Part, part_from_mesh

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
DATA = TESTS / "data"

WD = 400.0  # the default sensor's working distance
X, Y = np.eye(3)[0], np.eye(3)[1]

# ---- passes over the flat plate (conftest `plate`: top face at z = 0) ---------------------


def plate_swath(z_top: float = 0.0) -> Swath:
    """A pass along +x over the plate's middle at W_d above a top face at `z_top`."""
    u, v = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    return Swath(0, np.array([-320.0, 0, z_top + WD]), np.array([320.0, 0, z_top + WD]), u, v)


def straight(s_mm, h_mm=0.0, pitch=0.0, swath_index=0) -> Trajectory:
    """Stations `s_mm` along that pass at height offset `h_mm` and pitch `pitch` (rad)."""
    sw = Swath(0, np.array([-320.0, 0, 400.0]), np.array([320.0, 0, 400.0]), X, Y)
    s = np.asarray(s_mm, dtype=float)
    poses = sw.poses(s, np.full_like(s, h_mm), np.full_like(s, pitch))
    return Trajectory(poses, np.full(len(s), swath_index), np.ones(len(s), bool), planner="t")


# ---- parts built on call (a parameter varies, or a test changes them) ---------------------
SLOPE_DEG = 60.0
HEMISPHERE = PlanContext(ScanSpec(), views="auto")  # judged on what the upper hemisphere sees


def sloped_housing(length=600.0, width=400.0, height=150.0, slope_deg=SLOPE_DEG) -> Part:
    """A box-shaped housing whose four side walls slope at `slope_deg` from the horizontal."""
    inset = height / math.tan(math.radians(slope_deg))
    lo = [(x, y, 0.0) for x in (-length / 2, length / 2) for y in (-width / 2, width / 2)]
    hi = [
        (x, y, height)
        for x in (-length / 2 + inset, length / 2 - inset)
        for y in (-width / 2 + inset, width / 2 - inset)
    ]
    return part_from_mesh(trimesh.Trimesh(lo + hi).convex_hull, "housing")


BLOCK_BOX = "box:-160,-110,50,160,110,70"  # around the block's top (z = 60)


def plate_with_block() -> Part:
    """A 1500 x 1000 x 10 plate (top at z = 10) with a 300 x 200 x 50 block on its middle."""
    plate = trimesh.creation.box((1500.0, 1000.0, 10.0))
    plate.apply_translation((0, 0, 5.0))
    block = trimesh.creation.box((300.0, 200.0, 50.0))
    block.apply_translation((0, 0, 35.0))
    return part_from_mesh(trimesh.util.concatenate([plate, block]), "plate-block")


# ---- a part planned once per planner ------------------------------------------------------


class PartPlans:
    """`part` planned by each planner at most once, on first use: the paper's nominal raster
    (`plan_swaths`, auto direction) joined by `plan_path`, with `make_planner(name, roll=roll)`
    under the default ScanSpec; and each plan's metrics (`evaluate`) per fan size. Planners
    that do not roll (fixed, the v0 rl policy) give one plan whatever `roll` says. Tests read
    the plans, never change them."""

    def __init__(self, part: Part) -> None:
        self.part = part
        self.spec = ScanSpec()
        self._swaths: list[Swath] | None = None
        self._plans: dict[tuple[str, bool], Trajectory] = {}
        self._metrics: dict[tuple[str, bool, int], Metrics] = {}

    @property
    def swaths(self) -> list[Swath]:
        if self._swaths is None:
            self._swaths = plan_swaths(self.part, self.spec.sensor)
        return self._swaths

    def _key(self, name: str, roll: bool) -> tuple[str, bool]:
        planner = make_planner(name, roll=roll)
        return planner.name, planner.roll

    def plan(self, name: str, roll: bool = True) -> Trajectory:
        key = self._key(name, roll)
        if key not in self._plans:
            planner = make_planner(name, roll=roll)
            self._plans[key] = plan_path(self.part, self.spec, planner, self.swaths)
        return self._plans[key]

    def metrics(self, name: str, roll: bool = True, points_per_profile: int = 256) -> Metrics:
        key = (*self._key(name, roll), points_per_profile)
        if key not in self._metrics:
            traj = self.plan(name, roll)
            self._metrics[key] = evaluate(
                self.part, self.spec, traj, points_per_profile=points_per_profile
            )
        return self._metrics[key]


# ---- the sensor body vs a part, straight from FCL ------------------------------------------
_BVH: dict[int, fcl.CollisionObject] = {}


def fcl_distance(part: Part, sensor: SensorSpec, pose: np.ndarray) -> float:
    """Body vs part straight from FCL, for an independent check."""
    if id(part) not in _BVH:
        bvh = fcl.BVHModel()
        bvh.beginModel(len(part.mesh.vertices), len(part.mesh.faces))
        vertices, faces = np.asarray(part.mesh.vertices, float), np.asarray(part.mesh.faces)
        bvh.addSubModel(vertices, faces.astype(np.int32))
        bvh.endModel()
        _BVH[id(part)] = fcl.CollisionObject(bvh, fcl.Transform())
    lo, hi = sensor.body_bounds_mm
    rot = pose[:3, :3]
    box = fcl.CollisionObject(
        fcl.Box(*(hi - lo)), fcl.Transform(rot, rot @ (0.5 * (lo + hi)) + pose[:3, 3])
    )
    return fcl.distance(box, _BVH[id(part)], fcl.DistanceRequest(), fcl.DistanceResult())


# ---- the command line ---------------------------------------------------------------------


def run_cli(*args: str) -> Result:
    return CliRunner().invoke(app, list(args))


# ---- training -----------------------------------------------------------------------------


def tiny_config(out, **kw):
    """A learn(256)-sized PPO run: 2 updates of 2 x 64 steps, a small fan, no noise."""
    from scanplan.rl.learn.config import TrainConfig  # deferred: it loads torch

    base = {
        "output_dir": str(out),
        "total_timesteps": 256,
        "n_envs": 2,
        "n_steps": 64,
        "batch_size": 32,
        "n_epochs": 2,
        "checkpoint_every_updates": 1,
        "progress_bar": False,
        "command": "pytest tiny",
        "env": {"fan_points": 64, "noise": False, "segment_mm": (20.0, 40.0)},
        "bc_samples": 200,  # exercise the warm start too
    }
    return TrainConfig(**(base | kw))


def ppo(seed: int):
    """A small SB3 PPO on Pendulum (a model to checkpoint, not to train well)."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    return PPO(
        "MlpPolicy",
        gym.make("Pendulum-v1"),
        n_steps=64,
        batch_size=32,
        n_epochs=2,
        seed=seed,
        device="cpu",
    )


# ---- a pickled payload that must never run ------------------------------------------------


class Exploit:
    """Unpickling this creates `marker` (stands in for arbitrary code)."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def exploit_pickle(marker: Path) -> bytes:
    return pickle.dumps(Exploit(marker))


# ---- loaders: bad input of any shape ends in one clear line -------------------------------
FAST = settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def one_line_or_ok(load, path: Path) -> None:
    """`load(path)` returns, or raises a one-line ValueError naming the file."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy RuntimeWarning noise either
        try:
            load(path)
        except ValueError as exc:
            message = str(exc)
            assert message and "\n" not in message, message
            assert str(path) in message or path.name in message, message


SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
)
JSON_VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=5)
    ),
    max_leaves=30,
)


def recorded_trajectory() -> Trajectory:
    """One pass of 11 poses over the plate with every record a plan file carries: context,
    one view with its pass line, the arm (a rigid part pose and TCP) and a cycle time."""
    sw = plate_swath()
    s = np.linspace(0.0, 100.0, 11)
    poses = sw.poses(s, 0 * s, 0 * s)
    part_pose = np.eye(4)
    part_pose[:3, :3] = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    part_pose[:3, 3] = [500.0, -200.0, 100.0]
    meta = {
        "context": PlanContext(ScanSpec(), planner="feedback", part="plate").to_json_dict(),
        "views": [
            {
                "index": 0,
                "axis": [0.0, 0.0, 1.0],
                "first_swath": 0,
                "last_swath": 0,
                "passes": 1,
                "swaths": [swath_record(sw)],
            }
        ],
        "robot": {
            "robot": "ur10e",
            "part_pose": "500,-200,100,30,0,0",
            "T_base_part": part_pose.tolist(),
            "T_flange_sensor": np.eye(4).tolist(),
            "flyable": True,
        },
        "cycle_time_s": 12.5,
    }
    return Trajectory(poses, np.zeros(11, int), np.ones(11, bool), planner="feedback", meta=meta)


# ---- robot programs -----------------------------------------------------------------------


def plate_file(directory: Path, x_mm: float = 400.0, y_mm: float = 300.0) -> str:
    """An STL of a 10 mm plate whose top face is z = 0, centred on the origin: the part
    `export --part` and `place --part` check the arm's links against."""
    box = trimesh.creation.box((x_mm, y_mm, 10.0))
    box.apply_translation((0, 0, -5.0))
    path = Path(directory) / "plate.stl"
    box.export(path)
    return str(path)


def fixture_files(directory: Path, part: Part, share: float = 0.4) -> tuple[str, str]:
    """STLs of two fixtures of a plate lying along x (part coordinates): a 10 mm lid 5 mm
    above its top over the first `share` of its length (wider than the plate across), and
    a block 100 mm beside it that hides nothing. Returns (lid, beside)."""
    (x0, y0, _), (x1, y1, z1) = part.bounds
    length = share * (x1 - x0)
    lid = trimesh.creation.box((length, y1 - y0 + 40.0, 10.0))
    lid.apply_translation((x0 + length / 2, (y0 + y1) / 2, z1 + 5.0 + 5.0))
    beside = trimesh.creation.box((40.0, 40.0, 40.0))
    beside.apply_translation((x1 + 120.0, (y0 + y1) / 2, z1))
    paths = (Path(directory) / "lid.stl", Path(directory) / "beside.stl")
    lid.export(paths[0])
    beside.export(paths[1])
    return str(paths[0]), str(paths[1])


def snake_trajectory() -> Trajectory:
    """Three snake passes over a bumpy part: pitch varies along each pass, the sensor turns
    180° about its axis between passes, transitions lift clear and are not scanned. While
    scanning the laser line (W_d along the beam) follows the bumps 0.5 mm apart, so the
    sensor's origin swings with the pitch, as over a real part."""
    poses, swath, scanning = [], [], []
    wd = ScanSpec().working_distance_mm

    def add(xyz, yaw, pitch, k, scan):
        T = np.eye(4)
        down = Rotation.from_euler("zx", [yaw, np.pi]) * Rotation.from_euler("x", pitch)
        R = down.as_matrix()
        T[:3, :3], T[:3, 3] = R, np.asarray(xyz) - (wd * R[:, 2] if scan else 0.0)
        poses.append(T)
        swath.append(k)
        scanning.append(scan)

    for k in range(3):
        sign = 1 if k % 2 == 0 else -1
        y = 400.0 * k
        x0, x1 = (-20.0, 30.0) if sign > 0 else (30.0, -20.0)
        add([x0, y, 600.0], 0.0 if sign > 0 else np.pi, 0.0, k, False)  # transition, lifted
        xs = np.arange(x0, x1 + sign * 1e-9, sign * 0.5)
        for x in xs:
            z = 5.0 * np.sin(x / 7.0)  # the line on the part
            pitch = 0.3 * np.cos(x / 7.0)
            add([x, y + 0.1 * x, z], 0.0 if sign > 0 else np.pi, pitch, k, True)
        add([x1, y, 600.0], 0.0 if sign > 0 else np.pi, 0.0, k, False)
    return Trajectory(np.array(poses), swath, scanning)


EXPORT_OPTIONS = ExportOptions(
    part_pose=parse_pose_arg("500,-200,100,30,5,-10"),
    tcp=parse_pose_arg("12,-3,180,0,-15,90"),
    scan=ScanSpec(travel_speed_mm_s=300.0),
    blend_mm=0.2,
)


def rot_err(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of a⁻¹b, immune to quaternion sign."""
    return (
        Rotation.from_matrix(a[:, :3, :3]).inv() * Rotation.from_matrix(b[:, :3, :3])
    ).magnitude()


def listing(directory) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def overhang_part() -> Part:
    """A 300 x 500 x 30 mm plate over a 200 x 380 x 40 mm block: the block's four walls lie
    50-60 mm in under the plate's edge, reached only by a beam tilted well off vertical."""
    plate = trimesh.creation.box((300.0, 500.0, 30.0))
    plate.apply_translation((0, 0, 15.0))
    block = trimesh.creation.box((200.0, 380.0, 40.0))
    block.apply_translation((0, 0, -20.0))
    return part_from_mesh(trimesh.util.concatenate([plate, block]), "overhang")


def loopback_cluster(threads: int = 1):
    """A Dask cluster of one worker process on this machine, for the --scheduler tests
    (dask.distributed imported here: the tests that call this skip without it)."""
    from dask.distributed import LocalCluster

    return LocalCluster(
        n_workers=1,
        threads_per_worker=threads,
        processes=True,
        host="127.0.0.1",
        dashboard_address=":0",
    )


def full_disk(monkeypatch, fail_at: int = 1) -> list[int]:
    """Make the `fail_at`-th file the atomic writers (`core.files`) open for writing, and
    every later one, fail as on a full disk (ENOSPC); returns the writes tried."""
    real, tried = os.fdopen, []

    class Full:
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def fdopen(fd, mode="r", *args, **kwargs):
        f = real(fd, mode, *args, **kwargs)
        if "w" not in mode:
            return f
        tried.append(fd)
        return Full(f) if len(tried) >= fail_at else f

    monkeypatch.setattr(os, "fdopen", fdopen)  # `core.files` writes through it
    return tried


@contextmanager
def tcp_server(answer: Callable[[socket.socket], None]) -> Iterator[str]:
    """tcp://127.0.0.1:PORT (a port from the OS) whose every connection gets `answer`: a
    port that is no Dask scheduler, for the --scheduler tests."""
    server = socket.create_server(("127.0.0.1", 0))
    server.settimeout(0.1)  # the loop looks for its stop this often
    stop = threading.Event()
    kept: list[socket.socket] = []

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            kept.append(conn)
            answer(conn)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        stop.set()
        thread.join()
        server.close()
        for conn in kept:
            conn.close()


@dataclass(frozen=True)
class Endless:
    """A view raster that never returns in a worker process (a view not wanted any more);
    it creates the file `started` when it begins. Here, not in a test module: a worker
    process imports it by this module's name."""

    caller: int  # the pid of the process that makes it
    started: str

    def __call__(self, view_part, view):
        if os.getpid() == self.caller:
            raise ValueError("planned here")
        open(self.started, "w").close()
        while True:
            time.sleep(0.1)


@dataclass(frozen=True)
class DiesInAWorker:
    """A view raster whose worker process dies on its first view (killed, out of memory).
    Here, not in a test module: a worker process imports it by this module's name."""

    raster: ViewRaster

    def __call__(self, view_part, view):
        if multiprocessing.parent_process() is not None:
            os._exit(1)
        return self.raster(view_part, view)


class FakeArm:
    """A placed arm as the view choice asks it, for a fake that says only what it flies of
    a view (`flown`): whether it flies more than so many poses follows from that, as
    `PlacedArm.flown_beyond` answers."""

    def flown(self, part: Part, traj: Trajectory) -> Trajectory:
        raise NotImplementedError

    def flown_beyond(self, part: Part, traj: Trajectory, least: int) -> Trajectory | None:
        flown = self.flown(part, traj)
        return flown if flown.scanning.sum() > least else None
