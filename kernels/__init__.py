# OpenCL C sources of shadowcl, installed as the package data shadowcl/kernels.
