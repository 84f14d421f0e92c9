/* The shaders' real type: float, or double with -DCOROFEM_DOUBLE (the device needs shaderFloat64).
 * Included after `#extension GL_GOOGLE_include_directive : require`. */
#ifdef COROFEM_DOUBLE
#extension GL_ARB_gpu_shader_fp64 : require
#define real double
#define REAL_EPS 2.220446049250313e-16LF
#define REAL_TINY 1e-280LF
#else
#define real float
#define REAL_EPS 1.1920929e-07
#define REAL_TINY 1e-30
#endif
