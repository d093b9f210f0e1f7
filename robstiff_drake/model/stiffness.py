"""The two stiffness models of the paper, in plain numpy.

Conventional model, the paper's Eq. (1):  K_x = J^-T K_q J^-1, used here mostly in
compliance form  C_x = J C_q J^T  (C_q = K_q^-1), which needs no inversion
and stays valid at singular poses.

CCT model (conservative congruence transformation, Chen & Kao), the paper's
Eqs. (6)-(7):  K_x = J^-T (K_q - K_g) J^-1,  K_g = d(J^T F)/dq.

Units: wrench = (force N, moment N*m about the tool point, base frame);
joint stiffness N*m/rad; Cartesian compliance has blocks m/N, m/(N*m) = 1/N,
rad/N and rad/(N*m).  Deflections: dq in rad, dx = (dp in m, dphi in rad).
"""

import numpy as np

from robstiff_drake.errors import SingularPoseError
from robstiff_drake.model import kinematics as kin


def cartesian_compliance(J, joint_stiffness_Nm_per_rad):
    """C_x = J C_q J^T (6x6), valid at any pose."""
    c_q = 1.0 / np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
    return (J * c_q[..., None, :]) @ np.swapaxes(J, -1, -2)


def translational_compliance(J, joint_stiffness_Nm_per_rad):
    """Tool-point displacement per unit force at the tool point (3x3, m/N)."""
    Jv = J[..., :3, :]
    c_q = 1.0 / np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
    return (Jv * c_q[..., None, :]) @ np.swapaxes(Jv, -1, -2)


def singular_joints(J, rel_tol=1e-6):
    """If J loses rank, the 1-based joints whose alignment causes it; an empty
    tuple when J is well conditioned.

    The lost motion is J's null vector.  When the arm joints 1-3 take part in
    it (elbow or shoulder singularity), the wrist joints only follow them and
    the arm joints are named; otherwise the wrist joints are (axes 4 and 6
    aligned)."""
    _, s, vt = np.linalg.svd(J)
    if s[-1] > rel_tol * s[0]:
        return ()
    null = np.abs(vt[-1])
    offset = 0 if null[:3].max() > 0.1 * null.max() else 3
    part = null[offset:offset + 3]
    return tuple(int(i) + 1 + offset for i in np.flatnonzero(part > 0.1 * part.max()))


def describe_singularity(joints):
    """Words for the singularity named by ``singular_joints``."""
    joints = set(joints)
    if joints and joints <= {4, 5, 6}:
        return "wrist singularity: axes 4 and 6 are aligned (q5 = 0)"
    if 1 in joints:
        return "shoulder singularity: the wrist centre is on axis 1"
    if joints == {2, 3} or joints == {3}:
        return "elbow singularity: the arm is stretched or folded (axes 2 and 3 and the wrist centre in a line)"
    return "joints " + ", ".join(map(str, sorted(joints))) + " are aligned"


def cartesian_stiffness(J, joint_stiffness_Nm_per_rad, K_g=None, rel_tol=1e-6):
    """K_x = J^-T (K_q - K_g) J^-1 (6x6); conventional model when K_g is None.

    Raises SingularPoseError, naming the aligned joints, where J is not
    invertible (the compliance form still answers there)."""
    joints = singular_joints(J, rel_tol)
    if joints:
        raise SingularPoseError(
            "K_x does not exist at this pose, the Jacobian is singular ("
            + describe_singularity(joints)
            + f"; joints {', '.join(map(str, joints))}); use the compliance form C_x = J C_q J^T",
            joints,
        )
    K = np.diag(np.asarray(joint_stiffness_Nm_per_rad, dtype=float))
    if K_g is not None:
        K = K - K_g
    Jinv = np.linalg.inv(J)
    return Jinv.T @ K @ Jinv


def principal_axes(C3):
    """Eigenvalues (ascending) and unit eigenvectors (columns) of a symmetric
    3x3 compliance or stiffness matrix."""
    w, V = np.linalg.eigh(0.5 * (C3 + C3.T))
    return w, V


def deflection_conventional(J, joint_stiffness_Nm_per_rad, wrench):
    """Conventional model: dq = C_q J^T F (rad), dx = J dq (m, rad)."""
    tau = np.swapaxes(J, -1, -2) @ np.asarray(wrench, dtype=float)
    dq = tau / np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
    return dq, J @ dq


def deflection_cct(dh, q_rad, joint_stiffness_Nm_per_rad, wrench, tool_m=None):
    """CCT model: dq = (K_q - K_g)^-1 J^T F (rad), dx = J dq (m, rad)."""
    J = kin.jacobian(dh, q_rad, tool_m)
    K_g = kin.geometric_stiffness(dh, q_rad, wrench, tool_m)
    K = np.diag(np.asarray(joint_stiffness_Nm_per_rad, dtype=float)) - K_g
    dq = np.linalg.solve(K, J.T @ np.asarray(wrench, dtype=float))
    return dq, J @ dq


def deflection_exact(dh, q_rad, joint_stiffness_Nm_per_rad, wrench, tool_m=None,
                     tol_rad=1e-14, max_iter=50):
    """Large-deflection static equilibrium of the joint-spring model under a
    dead load (constant force and moment in the base frame, applied at the
    tool point): K_q dq = J(q + dq)^T F, solved by Newton's method whose
    tangent is exactly K_q - K_g.  Returns dq (rad) and the tool point's
    displacement (m), the reference against which both linear models are
    judged."""
    k = np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
    F = np.asarray(wrench, dtype=float)
    q0 = np.asarray(q_rad, dtype=float)
    dq = np.zeros(6)
    for _ in range(max_iter):
        q = q0 + dq
        J = kin.jacobian(dh, q, tool_m)
        residual = k * dq - J.T @ F
        tangent = np.diag(k) - kin.geometric_stiffness(dh, q, F, tool_m)
        step = np.linalg.solve(tangent, residual)
        dq = dq - step
        if np.max(np.abs(step)) < tol_rad:
            break
    else:
        raise RuntimeError("static equilibrium did not converge")
    dp = kin.tool_position(dh, q0 + dq, tool_m) - kin.tool_position(dh, q0, tool_m)
    return dq, dp


def kg_effect(dh, q_rad, joint_stiffness_Nm_per_rad, wrench, tool_m=None):
    """How much the K_g term changes the predicted tool-point deflection.

    Returns a dict (lengths in m):
      dp_conventional, dp_cct, dp_exact: tool-point displacement (3,) by the
        conventional model, the CCT model and the large-deflection equilibrium;
      relative_change: |dp_cct - dp_conv| / |dp_conv|, the paper's question;
      conventional_error, cct_error: |dp_model - dp_exact| / |dp_exact|.
    """
    J = kin.jacobian(dh, q_rad, tool_m)
    _, dx_conv = deflection_conventional(J, joint_stiffness_Nm_per_rad, wrench)
    _, dx_cct = deflection_cct(dh, q_rad, joint_stiffness_Nm_per_rad, wrench, tool_m)
    _, dp_exact = deflection_exact(dh, q_rad, joint_stiffness_Nm_per_rad, wrench, tool_m)
    dp_conv, dp_cct = dx_conv[:3], dx_cct[:3]
    n_conv = np.linalg.norm(dp_conv)
    n_exact = np.linalg.norm(dp_exact)
    return {
        "dp_conventional": dp_conv,
        "dp_cct": dp_cct,
        "dp_exact": dp_exact,
        "relative_change": float(np.linalg.norm(dp_cct - dp_conv) / n_conv) if n_conv > 0 else 0.0,
        "conventional_error": float(np.linalg.norm(dp_conv - dp_exact) / n_exact) if n_exact > 0 else 0.0,
        "cct_error": float(np.linalg.norm(dp_cct - dp_exact) / n_exact) if n_exact > 0 else 0.0,
    }
