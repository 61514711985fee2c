"""Independent closed-form kinematics of the reference eight-bar (circle intersections), for tests only.

It reads geometry (points, lengths) from the press file but shares no physics code with the package.
The branch signs are the ones press_reference.md verified.
"""
from __future__ import annotations

import numpy as np


def _circle(p0, r0, p1, r1, sign):
    d = p1 - p0
    dist = np.hypot(*d)
    a = (r0**2 - r1**2 + dist**2) / (2 * dist)
    h = np.sqrt(r0**2 - a**2)
    return p0 + a * d / dist + sign * h * np.array([-d[1], d[0]]) / dist


def _rot(t):
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def _angle(v):
    return np.arctan2(v[1], v[0])


class EightBar:
    """World COM positions and body angles of the reference press as functions of theta_c."""

    def __init__(self, press):
        self.press = press
        self.b = {n: b for n, b in press.bodies.items()}
        self.D = press.frame_points["D"]
        self.off = press.drive.angle_offset

    def pose(self, theta_c):
        """{body: (com_world[2], angle)} at crank angle theta_c (rad)."""
        b = self.b
        t1 = self.off + theta_c
        crank = b["crank"]
        R1 = _rot(t1)
        A = R1 @ crank.points["A"]
        B = R1 @ crank.points["B"]
        l3 = b["link3"]
        L3 = np.hypot(*(l3.points["C"] - l3.points["B"]))
        l4 = b["link4"]
        dc = np.hypot(*(l4.points["C"] - l4.points["D"]))
        C = _circle(B, L3, self.D, dc, +1)
        phi4 = _angle(C - self.D) - _angle(l4.points["C"] - l4.points["D"])
        R4 = _rot(phi4)
        E = self.D + R4 @ (l4.points["E"] - l4.points["D"])
        l5, l6, l7 = b["link5"], b["link6"], b["link7"]
        L5 = np.hypot(*(l5.points["E"] - l5.points["F"]))
        L6 = np.hypot(*(l6.points["F"] - l6.points["A"]))
        L7 = np.hypot(*(l7.points["G"] - l7.points["F"]))
        F = _circle(A, L6, E, L5, -1)
        G = np.array([0.0, F[1] - np.sqrt(L7**2 - F[0] ** 2)])

        def place(body, p_name, world_p, angle):
            return world_p + _rot(angle) @ (body.com - body.points[p_name]), angle

        phi3 = _angle(C - B) - _angle(l3.points["C"] - l3.points["B"])
        phi5 = _angle(E - F) - _angle(l5.points["E"] - l5.points["F"])
        phi6 = _angle(F - A) - _angle(l6.points["F"] - l6.points["A"])
        phi7 = _angle(G - F) - _angle(l7.points["G"] - l7.points["F"])
        return {
            "crank": place(crank, "O", np.zeros(2), t1),
            "link3": place(l3, "B", B, phi3),
            "link4": place(l4, "D", self.D, phi4),
            "link5": place(l5, "F", F, phi5),
            "link6": place(l6, "A", A, phi6),
            "link7": place(l7, "F", F, phi7),
            "slide": place(b["slide"], "G", G, 0.0),
        }

    def slide_y(self, theta_c):
        return self.pose(theta_c)["slide"][0][1]


def derivatives(f, x, h=1e-3):
    """First and second derivative of a smooth vector function by 5-point central differences (error ~h^4)."""
    f2, f1, f0, fm1, fm2 = (np.asarray(f(x + k * h)) for k in (2, 1, 0, -1, -2))
    d1 = (-f2 + 8 * f1 - 8 * fm1 + fm2) / (12 * h)
    d2 = (-f2 + 16 * f1 - 30 * f0 + 16 * fm1 - fm2) / (12 * h * h)
    return d1, d2
