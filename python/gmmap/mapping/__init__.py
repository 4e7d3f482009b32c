"""The mapping pipeline: frames, submaps, place recognition, the pose graph, frames between
robots, global maps, the planner, and the `Mapper` that runs them. No networks, files of
datasets or ground truth."""
