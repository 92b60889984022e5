/* amsfe_lifecycle.h: `amsfe node --managed` for the C node: the ROS 2 lifecycle state
 * machine of rcl_lifecycle (its services change_state, get_state, ... under the node's
 * name, the introspection ones `ros2 lifecycle list` asks included) driving when samples are
 * processed, as the Python managed node (ros/node.py):
 * configure (the node is configured from its parameter file at start: nothing more to do),
 * activate (samples processed from then on, the watchdogs' clocks restarted), deactivate
 * (the hold command published, samples dropped), cleanup, shutdown (the node stops, exit 0).
 * The services are served from the node's wait set between samples; a request allocates
 * (rcl's typed take), a transition is not on the sample path.
 * A response the middleware could not deliver (Fast DDS sends it only once the client's
 * response reader is matched, waiting 100 ms: on a loaded machine discovery takes longer,
 * and `ros2 lifecycle set` or a manager would wait forever) is kept and sent again at the
 * next serve, for up to LIFECYCLE_RESEND_S, while the node may block: not once samples flow
 * (each try can block 100 ms), when it is dropped with a line on stderr. */
#ifndef AMSFE_LIFECYCLE_H
#define AMSFE_LIFECYCLE_H

#include <rcl/rcl.h>
#include <rcl_lifecycle/rcl_lifecycle.h>

/* The services of the state machine served (the wait set's room for them): change_state,
 * get_state, get_available_states, get_available_transitions, get_transition_graph. */
#define LIFECYCLE_SERVICES 5

/* What a served transition asks of the node. */
enum lifecycle_event { LC_NONE = 0, LC_ACTIVATE, LC_DEACTIVATE, LC_SHUTDOWN };

/* Responses kept for a second try, and for how long [s]. */
#define LIFECYCLE_PENDING 8
#define LIFECYCLE_RESEND_S 10.0

/* The services, in the order of the wait set and of lifecycle_pending.service. */
enum lifecycle_service {
  LC_SRV_CHANGE_STATE = 0,
  LC_SRV_GET_STATE,
  LC_SRV_AVAILABLE_STATES,
  LC_SRV_AVAILABLE_TRANSITIONS,
  LC_SRV_TRANSITION_GRAPH
};

/* A response not delivered yet: the service, the request's header, and what the answer is
 * made of (the transition's outcome; the state when the request was served). */
typedef struct {
  rmw_request_id_t header;
  int service; /* enum lifecycle_service */
  int success;
  const rcl_lifecycle_state_t *state;
  double since; /* CLOCK_MONOTONIC [s] of the first try */
} lifecycle_pending;

typedef struct {
  rcl_lifecycle_state_machine_t sm;
  int enabled;
  lifecycle_pending pending[LIFECYCLE_PENDING];
  int n_pending;
} node_lifecycle;

/* The state machine and its services on `node` (0 or an rcl error). */
rcl_ret_t lifecycle_init(node_lifecycle *lc, rcl_node_t *node);
/* Its services into the wait set (cleared by the caller). */
rcl_ret_t lifecycle_wait_add(node_lifecycle *lc, rcl_wait_set_t *ws);
/* Serve every pending request; each transition that succeeded is reported to `on` (the
 * node's reaction: activate, deactivate, shutdown) before its response is sent.  Responses
 * not delivered before are tried again when `may_block` (the node is not processing samples);
 * otherwise they are dropped, each with a line. */
void lifecycle_serve(node_lifecycle *lc, int may_block, void (*on)(void *ctx, int event),
                     void *ctx);
/* Its label ("unconfigured", "inactive", "active", "finalized", ...). */
const char *lifecycle_state(const node_lifecycle *lc);
void lifecycle_fini(node_lifecycle *lc, rcl_node_t *node);

#endif /* AMSFE_LIFECYCLE_H */
