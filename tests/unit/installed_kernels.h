/* installed_kernels.h: what `make install` puts in PREFIX/share/terrafarm/kernels, the kernel
 * files and the C renderer's headers they share (the Makefile's KERNELS and KERNEL_SHARED), all
 * in one directory: the layout test_opencl and test_opencl_cache build a program from. */
#ifndef TF_TEST_INSTALLED_KERNELS_H
#define TF_TEST_INSTALLED_KERNELS_H

static const char *const installed_kernel_files[] = {
    "worker/kernels/tf_cl_params.h",  "worker/kernels/terrafarm.cl",
    "worker/kernels/packet.cl",       "worker/kernels/packet_trace.cl",
    "worker/kernels/packet_shade.cl", "worker/kernels/packet_render.cl",
    "common/portable.h",              "common/render/constants.h",
    "common/render/sample_math.h",    "common/render/trace_math.h",
    "common/render/sun_math.h",       "common/terrain/noise_kernel.h",
    "common/terrain/grid_height.h",
};
#define INSTALLED_KERNEL_FILES (sizeof installed_kernel_files / sizeof installed_kernel_files[0])

#endif
