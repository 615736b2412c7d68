"""Grasp tasks that grade a grip controller: a scene, a script of setpoints and disturbances, and
the metrics and limits that judge a run (`finger-sim tasks`, tasks in config/tasks/).

- `schema`: the task file (YAML) and its validation;
- `controllers`: the controller interface (`module:callable`) and the shipped controllers;
- `runner`: a task run against one controller (sampling, delay, crushing, disturbances);
- `ros_runner`: a task run against a ROS 2 controller node, through finger_node in lockstep;
- `metrics`: the scores, each defined on the run's sampled outputs, and pass/fail;
- `report`: Markdown tables, figures and JSON over tasks × controllers.
"""
