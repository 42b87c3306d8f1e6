"""Upper-limb joint kinematics from two IMUs: the constrained DH model of Caruso et al. (IEEE Access 2024).

* :mod:`.dh`: the ISB-consistent 6-joint Denavit-Hartenberg chain (Table 1), forward kinematics and
  analytic Jacobians (numba);
* :mod:`.solver`: per-sample unconstrained / constrained minimisation (joint limits, workspace boxes),
  warm-started (numba LM/SQP; SciPy reference);
* :mod:`.calibration`: IMU orientations to segment orientations in the trunk frame (neutral posture);
* :mod:`.errors`: e_tot / e_out (section II-F);
* :mod:`.pipeline`: all of it on two orientation series.

Angles are in radians here; user-facing parameters (limits, neutral posture, carrying angle) in degrees.
"""

from imulog.process.kinematics.calibration import NeutralCalibration, fit_global_to_trunk, segment_rotations
from imulog.process.kinematics.dh import (
    JOINT_LABELS,
    JOINT_NAMES,
    ArmModel,
    ForwardKinematics,
    JointLimits,
    forward_kinematics,
    jacobians,
)
from imulog.process.kinematics.errors import kinematics_errors, outside_workspace, rms_deg
from imulog.process.kinematics.pipeline import KinematicsConfig, KinematicsEstimate, estimate_kinematics
from imulog.process.kinematics.solver import (
    RealTimeSolver,
    SolveResult,
    SolverParams,
    Workspace,
    WorkspaceBox,
    solve_sample_scipy,
    solve_sequence,
)

__all__ = [
    "JOINT_LABELS",
    "JOINT_NAMES",
    "ArmModel",
    "ForwardKinematics",
    "JointLimits",
    "KinematicsConfig",
    "KinematicsEstimate",
    "NeutralCalibration",
    "RealTimeSolver",
    "SolveResult",
    "SolverParams",
    "Workspace",
    "WorkspaceBox",
    "estimate_kinematics",
    "fit_global_to_trunk",
    "forward_kinematics",
    "jacobians",
    "kinematics_errors",
    "outside_workspace",
    "rms_deg",
    "segment_rotations",
    "solve_sample_scipy",
    "solve_sequence",
]
