/* Private to core/ (and white-box tests): the cgroup part of hv__memory_limit. */
#ifndef HV_CORE_MEMORY_H
#define HV_CORE_MEMORY_H

#include <stddef.h>

/* The least memory limit of the cgroups that proc_cgroup (the format of
 * /proc/self/cgroup) names, read under sys_root (/sys/fs/cgroup): v2's
 * memory.max and v1's memory/.../memory.limit_in_bytes, of the group and of
 * each group above it; SIZE_MAX where none is set or none can be read. */
size_t hv__cgroup_memory_limit(const char *proc_cgroup, const char *sys_root);

#endif
