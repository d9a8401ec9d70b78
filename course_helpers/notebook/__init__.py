"""The notebook layer: what only makes sense in Jupyter (the %ros2 magics, quizzes, widgets)."""
