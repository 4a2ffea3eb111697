/* pocl_cachedir.h: PoCL's kernel cache directory as terrafarm chooses and keeps it.
 *
 * PoCL compiles programs into POCL_CACHE_DIR.  When the user set none, the OpenCL backend points
 * it at a per-user directory of terrafarm's own (tf_pocl_cache_dir_choose).  PoCL 3.1's start-up
 * creates an empty file named tempfile_XXXXXX in that directory and never removes it: one a
 * worker process, thousands on a farm that runs for weeks.  tf_pocl_cache_sweep removes those
 * left behind: only in terrafarm's own directory, only regular files of that name owned by this
 * user and older than TF_POCL_TEMPFILE_MAX_AGE_S (a PoCL at work writes and renames its temporary
 * files within seconds).  Every worker start sweeps, and the sweep looks at each such file, so
 * the age bounds its cost: with an hour, a machine busy with renders held ~2,500 of them and a
 * worker's start took 4 ms longer (bench/README.md section 42).  Every new kernel source or
 * driver adds a program directory there (a few hundred KB), which PoCL never removes:
 * tf_pocl_cache_prune removes those not used for a long time, likewise only in terrafarm's own
 * directory. */
#ifndef TF_POCL_CACHEDIR_H
#define TF_POCL_CACHEDIR_H

#include <stddef.h>
#include <time.h>

#define TF_POCL_TEMPFILE_MAX_AGE_S 300

/* Set POCL_CACHE_DIR, unless the user did, to $XDG_CACHE_HOME/terrafarm/pocl, else
 * $HOME/.cache/terrafarm/pocl, else /tmp/terrafarm-pocl-UID, whichever can be created private
 * and written; the chosen directory goes to dir (empty when the user chose, or none could be
 * made).  Must run before the first OpenCL call. */
void tf_pocl_cache_dir_choose(char *dir, size_t len);

/* Remove from dir every regular file named tempfile_ plus six characters, owned by this user,
 * last modified before now - max_age_s.  Symbolic links, directories, other names and other
 * users' files are left alone; dir itself is opened without following a link.  Returns how many
 * were removed, or -1 (errno set) if dir cannot be read; a file that vanished meanwhile (another
 * worker's sweep) is not an error. */
int tf_pocl_cache_sweep(const char *dir, time_t now, long max_age_s);

/* Remove from dir every program directory PoCL made (dir/XX/YYY..., both names of PoCL's hash
 * letters A to P) that is this user's and was last used before now - max_idle_s: its
 * last_accessed file's time (PoCL touches it whenever it builds a program from there), else the
 * directory's own.  A program directory is removed with all it holds, depth first, nothing
 * followed through a symbolic link (a link is removed as a name); an emptied XX goes too.  Other
 * names, other users' directories and dir given as a link are left alone.  Returns how many
 * program directories were removed, or -1 (errno set) if dir cannot be read. */
int tf_pocl_cache_prune(const char *dir, time_t now, long max_idle_s);

#endif
