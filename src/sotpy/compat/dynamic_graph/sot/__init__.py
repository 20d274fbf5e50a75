"""SoT's ``dynamic_graph.sot`` namespace, served by sotpy."""
