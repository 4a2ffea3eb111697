/* api.h: the dashboard's JSON documents (README "Dashboard and API"), built with jansson from
 * one snapshot (snapshot.h).  Pure functions: no locks, no I/O; httpd.c serves them and
 * `terrafarm status` reads the first.  Every time is in seconds; `*_s` fields count from the
 * start of the render unless named otherwise, and wall-clock instants are ISO 8601 UTC. */
#ifndef TF_API_H
#define TF_API_H

#include <jansson.h>
#include <stdint.h>

#include "coordinator/dashboard/snapshot.h"

json_t *tf_api_status(const tf_snapshot *s);          /* /api/status */
json_t *tf_api_workers(const tf_snapshot *s);         /* /api/workers */
json_t *tf_api_events(const tf_snapshot *s, uint64_t after); /* /api/events?after=SEQ */
json_t *tf_api_event(const tf_snapshot *s, const tf_event *e); /* one event (also for SSE) */
json_t *tf_api_tasks(const tf_snapshot *s);           /* /api/tasks */
json_t *tf_api_history(const tf_snapshot *s);         /* /api/history */

#endif
