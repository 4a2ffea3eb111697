/* pocl_binary.h: a PoCL 3.1 program binary rewritten to carry no LLVM IR, so that a process
 * creating its program from it never starts PoCL's compiler.
 *
 * The binary PoCL 3.1 gives for a built program (clGetProgramInfo CL_PROGRAM_BINARIES: the
 * "poclbin" format, version 9) holds the whole program as LLVM bitcode (program.bc, ~385 KB for
 * the kernels here) and every kernel compiled to a generic work-group function
 * (/KERNEL/0-0-0/KERNEL.so).  A program created from it has PoCL parse program.bc in
 * clBuildProgram, ~20 ms of CPU in every worker process, only to be able to compile work-group
 * functions specialised to a launch's local size; at one work-item a group (the kernels here)
 * those run no faster than the generic ones.  When neither the binary nor PoCL's cache
 * directory for it holds a program.bc, PoCL 3.1 takes the generic functions the binary carries
 * and parses nothing (lib/CL/devices/common.c, pocl_check_kernel_disk_cache).
 *
 * The rewrite: program.bc becomes an empty placeholder file (PoCL asserts the binary's root entry
 * is not empty), and the build hash, which names the binary's directory in PoCL's cache (where
 * the build from source left its program.bc), becomes one derived from `tag`.  The kernels'
 * records, metadata and compiled functions, are copied byte for byte.
 *
 * Other formats and versions are left alone: a newer PoCL writes another version, and this file
 * knows only the layout it was tested against. */
#ifndef TF_POCL_BINARY_H
#define TF_POCL_BINARY_H

#include <stddef.h>

#define TF_POCL_BINARY_VERSION 9 /* the poclbin format version PoCL 3.1 writes */
#define TF_POCL_TAG_BYTES 20     /* bytes of tag that make the new build hash */

/* The binary bin[0..n) without its IR, in *out (malloc'd, *outn bytes): 1.  0 when the rewrite
 * does not apply, with *out NULL: not a poclbin of TF_POCL_BINARY_VERSION, a root entry holding
 * more than program.bc, or a kernel without a generic work-group function (the caller keeps
 * the binary as it is).  -1 when the binary is cut short or its sizes do not add up, or memory
 * runs out. */
int tf_pocl_binary_without_ir(const unsigned char *bin, size_t n,
                              const unsigned char tag[TF_POCL_TAG_BYTES], unsigned char **out,
                              size_t *outn);

/* 1 when bin[0..n) is a poclbin that holds LLVM bitcode in a file of its root entry, 0 when it
 * holds none, -1 when it cannot be read as a poclbin of TF_POCL_BINARY_VERSION. */
int tf_pocl_binary_has_ir(const unsigned char *bin, size_t n);

#endif
