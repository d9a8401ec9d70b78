"""The course's ROS machinery, shared by every chapter: the bottom layer of ``course_helpers``.

It depends on rclpy and the standard library only (ipywidgets is imported lazily, and only
inside a Jupyter kernel, to show node consoles). Nothing here knows about chapters, checkers,
plots or the ``%ros2`` magics.

* ``runtime``: one ROS context and background executor per kernel (``get_runtime()``);
* ``executors``, ``node_hook``: the executor classes, the one spin loop, and the hook that
  builds a student's ``Node`` subclass in the runtime's context;
* ``waiting``: the one way to wait (``wait_until`` raises, ``poll_until`` returns a bool);
* ``processes``, ``channel``, ``child``: the one process layer, and the one structured
  channel on which a child reports to the kernel;
* ``domains``, ``dds_config``, ``shm_ports``: a ROS domain per kernel, machine-wide, how
  participants discover each other, and the shared-memory files old processes left behind;
* ``participants``, ``udp_sockets``, ``mapped_files``: which DDS participant holds a node (its GUID
  prefix in the graph), and what a process holds of Fast DDS (its UDP sockets and what each is for,
  its shared-memory files);
* ``netns``: private network namespaces whose processes are course children (a lossy link,
  two machines on one box);
* ``console``, ``logs``: node consoles under the cell that started a node;
* ``names``, ``validation``, ``qos_dict``, ``msg_yaml``, ``units``, ``versions``,
  ``errors``: small conversions and checks with errors a student can act on;
* ``build_interfaces``: the rosidl build of the course's interface packages (set-up).
"""
