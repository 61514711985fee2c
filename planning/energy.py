"""A plan's energy per stroke (summary.json ``energy``, power.csv, power.png): the motor torque and speed of
profile.csv's samples through :func:`press_model.energy.stroke_energy`, the dwell's holding torque included.

The mechanical parts: the process work (the job's force on the slide over its motion), the gear's loss (the shaft's
power less what the gear passes to the crank, :func:`press_model.motor.crank_input_torque`), and the rest of the
shaft's work as the joints' and guide's friction (the linkage's kinetic, potential and balance energy return to
their start over the periodic stroke)."""
from __future__ import annotations

import math

import numpy as np

from press_model.energy import stroke_energy
from press_model.forces import ProcessForce
from press_model.model import PressModel
from press_model.motor import crank_input_torque
from press_model.power_flow import trapezoid_weights

RPM_TO_RAD_S = 2.0 * math.pi / 60.0


def plan_energy(pm: PressModel, process: ProcessForce, cols: dict):
    """(power flow or None, the summary's ``energy``) of a plan sampled as profile.csv's columns ``cols`` (one
    periodic cycle: the first and last samples are its start and end)."""
    drive = pm.press.drive
    t = np.asarray(cols["time_s"], float)
    w = trapezoid_weights(t)
    torque = np.asarray(cols["motor_torque_Nm"], float)
    crank_speed = np.asarray(cols["crank_speed_rad_s"], float)
    shaft_net = float(np.sum(drive.motors * drive.gear_ratio * torque * crank_speed * w))
    h, hd = np.asarray(cols["slide_height_m"], float), np.asarray(cols["slide_velocity_m_s"], float)
    process_work = float(np.sum(-process(h, hd) * hd * w))
    crank_side = crank_input_torque(drive, torque, crank_speed) * crank_speed
    gear = float(np.sum((drive.motors * drive.gear_ratio * torque * crank_speed - crank_side) * w))
    mechanical = {"gear_J": gear, "friction_J": shaft_net - gear - process_work, "process_work_J": process_work}
    flow, en = stroke_energy(pm.press, torque, crank_speed * drive.gear_ratio, w, mechanical)
    en["friction_is"] = ("the shaft's net work less the gear's loss and the process work: joint and guide friction (the "
                         "linkage's kinetic, potential and balance energy return over the periodic stroke)")
    return flow, en
