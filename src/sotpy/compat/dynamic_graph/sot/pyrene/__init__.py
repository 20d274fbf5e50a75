"""sot-talos' ``dynamic_graph.sot.pyrene`` (LAAS' Talos, Pyrene), served by sotpy."""
