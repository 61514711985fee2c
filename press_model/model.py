"""The press as a Pinocchio model with loop closures: constants in :class:`PressModel`, buffers in :class:`Workspace`.

Following Pinocchio's Model/Data split, a :class:`PressModel` never changes after construction; a
:class:`Workspace` holds the Pinocchio ``Data`` and warm-start state of one caller. Algorithms are
free functions in :mod:`kinematics` and :mod:`dynamics` that take both.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pinocchio as pin

from .disk_cache import cached_assembly
from press_io.errors import PressDataError
from .forces import check_balance_compression
from .kinematics import LWA, assembly_sweep
from .press_data import FRAME, PressData
from .reaction_fixed_point import friction_constants
from .urdf import loops_dict, marker, read_loops, spanning_tree, urdf_text



@dataclass(frozen=True)
class CutJoint:
    name: str
    kind: str
    first_frame: int  # Pinocchio frame id of the point on the first body
    second_frame: int


def build_pinocchio(urdf: str, loops: dict) -> tuple[pin.Model, list[dict]]:
    """Parse a URDF string into a Pinocchio model with the loop file's gravity; returns (model, cut list)."""
    model = pin.buildModelFromXML(urdf)
    model.gravity.linear = np.asarray(loops["gravity_m_s2"], dtype=float)
    if model.nq != model.nv:
        raise PressDataError("<urdf>", "joints", model.nq, "every joint must have one coordinate (revolute about z or prismatic)")
    return model, list(loops["cut_joints"])


def load_urdf_model(urdf_path) -> tuple[pin.Model, list[dict]]:
    """Read a URDF written by :func:`urdf.write_urdf` and its loop file back into Pinocchio."""
    path = Path(urdf_path)
    return build_pinocchio(path.read_text(encoding="utf-8"), read_loops(path))


class PressModel:
    """Constants of one press: the Pinocchio tree, loop closures, and the index maps of the press data.

    Constructing it checks that the linkage assembles over the whole crank turn (see
    :func:`kinematics.assembly_sweep`) and raises :class:`AssemblyError` otherwise.
    """

    def __init__(self, press: PressData, check_assembly: bool = True):
        self.press = press
        self.tree = spanning_tree(press)
        self.model, cuts = build_pinocchio(urdf_text(press), loops_dict(press, "press.urdf"))
        m = self.model
        self.nv = m.nv
        fid = {}
        for bname, pts in [(FRAME, press.frame_points)] + [(b, press.bodies[b].points) for b in press.bodies]:
            for pname in pts:
                fid[(bname, pname)] = m.getFrameId(marker(bname, pname))
        self.frame_id = fid
        self.cuts = tuple(
            CutJoint(c["name"], c["type"], m.getFrameId(c["first_frame"]), m.getFrameId(c["second_frame"])) for c in cuts
        )
        if any(c.kind != "revolute" for c in self.cuts):
            raise PressDataError(press.source, "tree.cut_joints", [c.name for c in self.cuts], "only revolute joints can be cut")
        self.n_loop_rows = 2 * len(self.cuts)
        # the two points of every cut (first, second, per cut) and the tree coordinates each point's frame Jacobian
        # has columns for (the joints supporting its body): loop_terms forms the loop Jacobian from data.J with them
        self.cut_frames = tuple(f for c in self.cuts for f in (c.first_frame, c.second_frame))
        self.cut_support = np.zeros((len(self.cut_frames), self.nv), dtype=bool)
        for k, f in enumerate(self.cut_frames):
            for jid in m.supports[m.frames[f].parentJoint][1:]:  # the universe (0) has no coordinate
                self.cut_support[k, m.joints[jid].idx_v] = True
        if self.n_loop_rows + 1 != self.nv:
            raise PressDataError(press.source, "joints", list(press.joints), f"tree has {self.nv} coordinates but {self.n_loop_rows} loop equations + 1 drive")
        # body -> Pinocchio joint that carries it
        self.body_joint = {b: m.frames[m.getFrameId(b)].parentJoint for b in press.bodies}
        self.tree_joint_id = {t.name: m.getJointId(t.name) for t in self.tree.joints}
        self.tree_joint_v = {t.name: m.joints[self.tree_joint_id[t.name]].idx_v for t in self.tree.joints}

        data = m.createData()
        q0 = pin.neutral(m)
        pin.computeJointJacobians(m, data, q0)
        rows = {FRAME: np.zeros(self.nv)}
        for b, jid in self.body_joint.items():
            # planar tree: a body's angle is a fixed sum of joint coordinates, so its row is constant
            rows[b] = pin.getJointJacobian(m, data, jid, LWA)[5].copy()
        self.angle_row = rows
        self.crank_row = rows[press.drive.crank_body]
        self.joint_rows = np.array([rows[j.first[0]] - rows[j.second[0]] for j in press.revolute_joints])
        self.joint_names = tuple(j.name for j in press.revolute_joints)
        self.bearing_radii = np.array([j.bearing_radius for j in press.revolute_joints])
        self.axis = np.array([press.guide.axis[0], press.guide.axis[1], 0.0])
        self.slide_frame = fid[(press.slide_body, press.slide_point)]
        self.slide_joint = self.body_joint[press.slide_body]

        # subtree membership: which tree joints carry the forces applied to a body
        self.tree_names = tuple(t.name for t in self.tree.joints)
        children = {}
        for t in self.tree.joints:
            children.setdefault(t.parent, []).append(t)
        carried = {}
        for t in reversed(self.tree.joints):
            below = {t.child}
            for c in children.get(t.child, []):
                below |= carried[c.name]
            carried[t.name] = below
        self.carries = {name: frozenset(bodies) for name, bodies in carried.items()}

        self.total_mass = sum(b.mass for b in press.bodies.values())
        self.assembly = None
        if check_assembly:
            # a press with absurd numbers (a point at 1e300 m) overflows inside Newton; the sweep's own checks
            # turn that into an AssemblyError, so numpy's warnings would only clutter the one-line message
            with np.errstate(all="ignore"):
                self.assembly = cached_assembly(press, lambda: assembly_sweep(self, Workspace(self)))
            check_balance_compression(press, self.assembly.stroke)

    def workspace(self) -> "Workspace":
        """Fresh work buffers for one caller of the algorithms (Pinocchio Data, warm start)."""
        return Workspace(self)

    @cached_property
    def reaction_map(self) -> "ReactionMap":
        """Constant maps from loop and slide forces to the force each tree joint carries (derived, built on first use)."""
        return ReactionMap(self)

    @cached_property
    def friction_constants(self) -> tuple:
        """The constants of the inverse dynamics' friction fixed point (:func:`reaction_fixed_point.friction_constants`)."""
        return friction_constants(self)

    @cached_property
    def drive_v_index(self) -> int:
        return self.tree_joint_v[self.press.drive.crank_joint]


class ReactionMap:
    """Constant maps from loop and slide forces to the force each tree joint carries (built per model)."""

    def __init__(self, pm: PressModel):
        press = pm.press
        n_tree, n_cut = len(pm.tree_names), len(pm.cuts)
        self.cut_coef = np.zeros((n_tree, n_cut))
        self.slide_coef = np.zeros(n_tree)
        for i, name in enumerate(pm.tree_names):
            carried = pm.carries[name]
            for c, cut in enumerate(pm.cuts):
                j = press.joints[cut.name]
                self.cut_coef[i, c] = (j.first[0] in carried) - (j.second[0] in carried)
            self.slide_coef[i] = press.slide_body in carried
        tree_index = {n: i for i, n in enumerate(pm.tree_names)}
        cut_index = {c.name: i for i, c in enumerate(pm.cuts)}
        self.revolute_tree = np.array([tree_index.get(j.name, -1) for j in press.revolute_joints])
        self.revolute_cut = np.array([cut_index.get(j.name, -1) for j in press.revolute_joints])
        self.guide_tree = tree_index[press.guide.name]
        self.tree_jids = [pm.tree_joint_id[n] for n in pm.tree_names]


class Workspace:
    """Work buffers of one caller: Pinocchio data and the last configuration (a warm start)."""

    def __init__(self, pm: PressModel):
        self.data = pm.model.createData()
        self.q_last = None
        self.K_last = None  # the constraint matrix at q_last (kinematics.loop_terms')
        self.theta_last = None
