//! Safe access to OpenVDB files through a C++ shim (see shim/). Not yet built.
