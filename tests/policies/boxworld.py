"""A table of axis-aligned boxes that answers the geometric questions the expert asks of
`SimEnv` (object boxes, corners, vertical rays, regions, joints, the robot's base), so its
geometry (placement, grasps, put-aside spots) is tested on synthetic scenes without LIBERO.

Nothing here moves: the expert's geometry only reads. Bodies stand upright (identity
rotation); an object's body origin is its first box's bottom centre unless given.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.policies.scripted.scene import Scene
from pipeline.sim.facts import JointFrame, JointKind, Region

TABLE_TOP = 0.9
BASE = np.array([-0.66, 0.0, TABLE_TOP])  # the robot's base, as in LIBERO's table scenes


def box(centre, size) -> np.ndarray:
    """A (2, 3) [lo, hi] box from its centre and full size."""
    c, h = np.asarray(centre, dtype=float), np.asarray(size, dtype=float) / 2
    return np.array([c - h, c + h])


def standing(xy, size) -> np.ndarray:
    """A box of `size` standing on the table at `xy`."""
    return box([xy[0], xy[1], TABLE_TOP + size[2] / 2], size)


@dataclass
class BoxWorld:
    objects: dict[str, list[np.ndarray]] = field(default_factory=dict)  # movable: name -> boxes
    fixtures: dict[str, list[np.ndarray]] = field(default_factory=dict)
    regions: dict[str, Region] = field(default_factory=dict)
    joints: dict[str, tuple[JointFrame, list[np.ndarray]]] = field(default_factory=dict)  # frame, part boxes
    origins: dict[str, np.ndarray] = field(default_factory=dict)  # body origins other than the default
    eef: np.ndarray = field(default_factory=lambda: np.array([-0.2, 0.0, 1.2]))
    goal: list[tuple[str, ...]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.fixtures.setdefault("table", [box([0.0, 0.0, TABLE_TOP - 0.05], [1.6, 1.6, 0.1])])

    # ---- what SimEnv answers -----------------------------------------------------------------
    @property
    def object_names(self) -> list[str]:
        return list(self.objects)

    @property
    def fixture_names(self) -> list[str]:
        return list(self.fixtures)

    @property
    def region_names(self) -> list[str]:
        return list(self.regions)

    def object_boxes(self, name: str) -> np.ndarray:
        boxes = self.objects.get(name, self.fixtures.get(name))
        if boxes is None:
            raise KeyError(name)
        return np.array(boxes, dtype=float).reshape(-1, 2, 3)

    def object_aabb(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        b = self.object_boxes(name)
        return b[:, 0].min(axis=0), b[:, 1].max(axis=0)

    def object_corners(self, name: str) -> np.ndarray:
        return np.array([[b[i, 0], b[j, 1], b[k, 2]] for b in self.object_boxes(name)
                         for i in (0, 1) for j in (0, 1) for k in (0, 1)])

    def object_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        if name in self.origins:
            return np.array(self.origins[name], dtype=float), np.array([1.0, 0.0, 0.0, 0.0])
        b = self.object_boxes(name)[0]
        return np.array([(b[0, 0] + b[1, 0]) / 2, (b[0, 1] + b[1, 1]) / 2, b[0, 2]]), np.array([1.0, 0.0, 0.0, 0.0])

    def object_frame(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        return self.object_pose(name)[0], np.eye(3)

    def object_com(self, name: str) -> np.ndarray:
        b = self.object_boxes(name)
        vol = np.prod(b[:, 1] - b[:, 0], axis=1)
        return ((b[:, 0] + b[:, 1]) / 2 * vol[:, None]).sum(axis=0) / vol.sum()

    def ray_down(self, xy, z_from: float, z_to: float, ignore: str | None = None) -> float | None:
        tops = [float(b[1, 2]) for n, bs in (self.objects | self.fixtures).items() if n != ignore for b in bs
                if b[0, 0] <= xy[0] <= b[1, 0] and b[0, 1] <= xy[1] <= b[1, 1] and z_to < b[1, 2] <= z_from]
        return max(tops) if tops else None

    def is_region(self, name: str) -> bool:
        return name in self.regions

    def region(self, name: str) -> Region:
        return self.regions[name]

    def joint_frame(self, joint: str) -> JointFrame:
        return self.joints[joint][0]

    def joint_part_boxes(self, joint: str) -> np.ndarray:
        return np.array(self.joints[joint][1], dtype=float).reshape(-1, 2, 3)

    def robot_base(self) -> np.ndarray:
        return BASE.copy()

    def eef_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.eef.copy(), np.diag([1.0, -1.0, -1.0])  # pointing down

    def gripper_opening(self) -> float:
        return 0.08

    def contacts(self) -> set:
        return set()

    def finger_contacts(self) -> tuple[set, set]:
        return set(), set()

    def goal_conjuncts(self) -> list:
        return [(tuple(c), False) for c in self.goal]

    def scene(self) -> Scene:
        return Scene(self)


def drawer(name: str, centre, inner, wall: float = 0.01, height: float = 0.08, axis=(1.0, 0.0, 0.0),
           parent: str = "cabinet_1") -> tuple[Region, tuple[JointFrame, list[np.ndarray]], str]:
    """A drawer region (inner half size `inner`, xy) with its four walls and floor as the
    slide joint's parts (add them to the parent fixture's boxes too, as LIBERO has them)."""
    c = np.asarray(centre, dtype=float)
    hx, hy = inner
    floor_z = c[2]
    parts = [box([c[0], c[1], floor_z - 0.005], [2 * hx + 2 * wall, 2 * hy + 2 * wall, 0.01])]
    for s in (-1, 1):
        parts.append(box([c[0] + s * (hx + wall / 2), c[1], floor_z + height / 2], [wall, 2 * hy + 2 * wall, height]))
        parts.append(box([c[0], c[1] + s * (hy + wall / 2), floor_z + height / 2], [2 * hx, wall, height]))
    joint = f"{name}_joint"
    region = Region(pos=np.array([c[0], c[1], floor_z + height / 2]), mat=np.eye(3),
                    size=np.array([hx, hy, height / 2]), parent=parent, joints=(joint,))
    frame = JointFrame(anchor=c.copy(), axis=np.asarray(axis, dtype=float), qpos=-0.15,
                       range=np.array([-0.16, 0.01]), kind=JointKind.SLIDE)
    return region, (frame, parts), joint
