"""Tooling for running and inspecting the node graph (no node imports it): the node processes on an isolated
DDS domain (``processes``), the foreground graph (``runner``), hosts in network namespaces (``netns``), a
throwaway PostgreSQL server for Optuna studies shared by hosts (``postgres``), the pip-only ros2cli
stand-ins (``ros2cli``, ``ros2cli_graph``, ``ros2cli_pub``) and the Foxglove layout."""
