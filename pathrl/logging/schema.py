"""MCAP topics and message layouts of pathrl's files, shared by their writers and readers.

``run.mcap`` (training runs: :class:`pathrl.train.mcap_logger.McapLogWriter`, :mod:`pathrl.industrial.rl_train`):

* :data:`RUN_CONFIG` once: ``{"config": resolved config, "train_cfg": RSL-RL train cfg}``;
* :data:`TRAIN_SCALARS` per iteration: ``{"iteration": int, "values": {tag: float}}``.

``episodes.mcap`` (evaluation: :func:`pathrl.eval.evaluate.write_episodes_mcap`), per episode ``e`` and
decision step ``t`` (s):

* :data:`EVAL_ROBOT` once (:data:`ROBOT_SCHEMA`): robot, joint_names, path_joints, ``<quantity>_limits`` (D, 2)
  for the :data:`LIMIT_FIELDS`, urdf, tcp_links;
* :data:`EVAL_REFERENCE`: episode, path, s (R,), position (R, M), tcp_position (R, T, 3);
* :data:`EVAL_JOINT_STATE` (:data:`JOINT_STATE_SCHEMA`): episode, t, position, velocity, acceleration (D,);
* :data:`EVAL_TCP`: episode, t, position (T, 3), orientation_xyzw (T, 4);
* :data:`EVAL_TASK` (optional): episode, t and task feedback series (ball on the plate, pelvis tilt);
* :data:`EVAL_EPISODE_METRICS`: the episode's metrics (:mod:`pathrl.eval.metrics`).

Other ``/eval/<name>`` channels with ``episode`` and ``t`` are optional extras (the viewer draws their
``position`` as points).
"""

from __future__ import annotations

__all__ = [
    "EPISODE_TOPICS", "EVAL_EPISODE_METRICS", "EVAL_JOINT_STATE", "EVAL_PREFIX", "EVAL_REFERENCE", "EVAL_ROBOT",
    "EVAL_TASK", "EVAL_TCP", "INDUSTRIAL_ERROR", "INDUSTRIAL_EXECUTED", "INDUSTRIAL_SUMMARY", "INDUSTRIAL_TARGET",
    "INDUSTRIAL_TOPICS", "INDUSTRIAL_WAYPOINTS", "JOINT_STATE_SCHEMA", "JOINT_STATE_SCHEMA_NAME", "KNOWN_EVAL",
    "LIMIT_FIELDS", "ROBOT_SCHEMA", "ROBOT_SCHEMA_NAME", "RUN_CONFIG", "RUN_TOPICS", "TRAIN_SCALARS",
    "TRUEADAPT_EPISODE", "TRUEADAPT_ROBOT", "TRUEADAPT_STEP", "TRUEADAPT_TOPICS",
]

RUN_CONFIG = "/run/config"
TRAIN_SCALARS = "/train/scalars"
RUN_TOPICS = (TRAIN_SCALARS, RUN_CONFIG)

EVAL_PREFIX = "/eval/"
EVAL_ROBOT = "/eval/robot"
EVAL_REFERENCE = "/eval/reference"
EVAL_JOINT_STATE = "/eval/joint_state"
EVAL_TCP = "/eval/tcp"
EVAL_TASK = "/eval/task"
EVAL_EPISODE_METRICS = "/eval/episode_metrics"
#: the channels an episodes file must have
EPISODE_TOPICS = (EVAL_ROBOT, EVAL_JOINT_STATE)
KNOWN_EVAL = {EVAL_ROBOT, EVAL_REFERENCE, EVAL_JOINT_STATE, EVAL_TCP, EVAL_EPISODE_METRICS}

#: limit fields of the robot message, in the order position, velocity, acceleration, jerk
LIMIT_FIELDS = ("position_limits", "velocity_limits", "acceleration_limits", "jerk_limits")

ROBOT_SCHEMA_NAME = "pathrl.RobotDescription"
ROBOT_SCHEMA = {"type": "object", "properties": {"robot": {"type": "string"}, "joint_names": {"type": "array"},
                "position_limits": {"type": "array"}, "velocity_limits": {"type": "array"},
                "acceleration_limits": {"type": "array"}, "jerk_limits": {"type": "array"},
                "urdf": {"type": "string"}}}
JOINT_STATE_SCHEMA_NAME = "pathrl.JointState"
JOINT_STATE_SCHEMA = {"type": "object", "properties": {"episode": {"type": "integer"}, "t": {"type": "number"},
                      "position": {"type": "array"}, "velocity": {"type": "array"},
                      "acceleration": {"type": "array"}}}

# ``industrial.mcap`` (one waypoint optimisation of the motion-profile task: :mod:`pathrl.industrial.record`);
# positions in mm, log time = iteration k seconds:
#
# * INDUSTRIAL_TARGET once: name, pose, move, speed_mm_s, method, policy, positions (n, 3), z_axis (n, 3);
# * per iteration k (0 = the baseline profile): INDUSTRIAL_WAYPOINTS (iteration, positions (m, 3)),
#   INDUSTRIAL_EXECUTED (iteration, t (N,) s, positions (N, 3)) and INDUSTRIAL_ERROR (iteration, max_pos_mm,
#   mean_pos_mm, max_ori_deg, mean_speed, speed_std, speed_std_ratio, profile_mm (N,) per executed sample,
#   target_index (N,) fractional index of each sample's nearest target point);
# * INDUSTRIAL_SUMMARY once: method, iterations, best_iteration, iterations_to_spec, executions, t_opt_s, history.
INDUSTRIAL_TARGET = "/industrial/target"
INDUSTRIAL_WAYPOINTS = "/industrial/waypoints"
INDUSTRIAL_EXECUTED = "/industrial/executed"
INDUSTRIAL_ERROR = "/industrial/error"
INDUSTRIAL_SUMMARY = "/industrial/summary"
#: the channels an industrial.mcap must have
INDUSTRIAL_TOPICS = (INDUSTRIAL_TARGET, INDUSTRIAL_EXECUTED)

# ``trueadapt.mcap`` (TrueAdapt adaptation episodes: :mod:`pathrl.eval.trueadapt_record`), positions
# in m and rad, log time = the episode's time on a back-to-back clock:
#
# * TRUEADAPT_ROBOT once: the EVAL_ROBOT layout plus mode, dt, plate_size (3,);
# * TRUEADAPT_STEP per episode and decision step (step 0 = the initial state): episode, step, t (s),
#   reference (D,), position / velocity / acceleration (D,) commanded (adapted), reference_tcp (3,), tcp (3,),
#   plate_quat_xyzw (4,) of the adapted plate, ball_xy (2,) in the plate frame, ball_position (3,) in the world,
#   ball_radius, failed (sticky: the task has failed), deviation (max |q - q_ref|, rad);
# * TRUEADAPT_EPISODE when an episode ends: episode, trajectory (bank index), steps, success, failed,
#   dev_terminated, fraction, acc, jerk, offset (the metrics of :mod:`pathrl.eval.trueadapt`).
TRUEADAPT_ROBOT = "/trueadapt/robot"
TRUEADAPT_STEP = "/trueadapt/step"
TRUEADAPT_EPISODE = "/trueadapt/episode"
#: the channels a trueadapt.mcap must have
TRUEADAPT_TOPICS = (TRUEADAPT_ROBOT, TRUEADAPT_STEP)
