"""The closed loop in one process: camera -> wire CNN -> DROAN -> planner -> setpoints."""
