/* amsfe_lifecycle.c: see amsfe_lifecycle.h. */
#define _GNU_SOURCE /* clock_gettime */
#include "amsfe_lifecycle.h"

#include <rcl_lifecycle/default_state_machine.h>
#include <rcutils/error_handling.h>
#include <lifecycle_msgs/msg/state.h>
#include <lifecycle_msgs/msg/transition.h>
#include <lifecycle_msgs/msg/transition_description.h>
#include <lifecycle_msgs/msg/transition_event.h>
#include <lifecycle_msgs/srv/change_state.h>
#include <lifecycle_msgs/srv/get_available_states.h>
#include <lifecycle_msgs/srv/get_available_transitions.h>
#include <lifecycle_msgs/srv/get_state.h>
#include <rosidl_runtime_c/string_functions.h>

#include <stdio.h>
#include <string.h>
#include <time.h>

rcl_ret_t lifecycle_init(node_lifecycle *lc, rcl_node_t *node) {
  memset(lc, 0, sizeof *lc);
  lc->sm = rcl_lifecycle_get_zero_initialized_state_machine();
  rcl_lifecycle_state_machine_options_t opts = rcl_lifecycle_get_default_state_machine_options();
  opts.enable_com_interface = true;
  opts.initialize_default_states = true;
  rcl_ret_t ret = rcl_lifecycle_state_machine_init(
      &lc->sm, node, ROSIDL_GET_MSG_TYPE_SUPPORT(lifecycle_msgs, msg, TransitionEvent),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, ChangeState),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, GetState),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, GetAvailableStates),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, GetAvailableTransitions),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, GetAvailableTransitions), &opts);
  lc->enabled = ret == RCL_RET_OK;
  return ret;
}

static rcl_service_t *service_of(node_lifecycle *lc, int which);

rcl_ret_t lifecycle_wait_add(node_lifecycle *lc, rcl_wait_set_t *ws) {
  rcl_ret_t ret = RCL_RET_OK;
  for (int i = 0; i < LIFECYCLE_SERVICES && ret == RCL_RET_OK; ++i)
    ret = rcl_wait_set_add_service(ws, service_of(lc, i), NULL);
  return ret;
}

const char *lifecycle_state(const node_lifecycle *lc) {
  return lc->sm.current_state ? lc->sm.current_state->label : "unknown";
}

/* One transition by id through its intermediate state ("configuring", ...) to its goal:
 * 1 done (the node's reaction run), 0 not a transition of the current state. */
static int transition(node_lifecycle *lc, uint8_t id, void (*on)(void *, int), void *ctx) {
  if (rcl_lifecycle_trigger_transition_by_id(&lc->sm, id, true) != RCL_RET_OK) {
    rcutils_reset_error();
    return 0;
  }
  int event = LC_NONE;
  switch (id) {
    case lifecycle_msgs__msg__Transition__TRANSITION_ACTIVATE: event = LC_ACTIVATE; break;
    case lifecycle_msgs__msg__Transition__TRANSITION_DEACTIVATE: event = LC_DEACTIVATE; break;
    case lifecycle_msgs__msg__Transition__TRANSITION_UNCONFIGURED_SHUTDOWN:
    case lifecycle_msgs__msg__Transition__TRANSITION_INACTIVE_SHUTDOWN:
    case lifecycle_msgs__msg__Transition__TRANSITION_ACTIVE_SHUTDOWN: event = LC_SHUTDOWN; break;
    default: break;
  }
  if (event != LC_NONE && on) on(ctx, event);
  if (rcl_lifecycle_trigger_transition_by_label(&lc->sm, rcl_lifecycle_transition_success_label,
                                                true) != RCL_RET_OK) {
    rcutils_reset_error();
    return 0;
  }
  return 1;
}

static double mono_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* A lifecycle_msgs/State from one of the machine's states. */
static void state_msg(lifecycle_msgs__msg__State *m, const rcl_lifecycle_state_t *st) {
  m->id = (uint8_t)st->id;
  rosidl_runtime_c__String__assign(&m->label, st->label);
}

/* `count` transitions of `list` as TransitionDescriptions (id, label, start, goal). */
static void describe_transitions(lifecycle_msgs__msg__TransitionDescription__Sequence *out,
                                 const rcl_lifecycle_transition_t *list,
                                 unsigned int count) {
  if (!lifecycle_msgs__msg__TransitionDescription__Sequence__init(out, count)) return;
  for (unsigned int i = 0; i < count; ++i) {
    const rcl_lifecycle_transition_t *t = &list[i];
    lifecycle_msgs__msg__TransitionDescription *d = &out->data[i];
    d->transition.id = (uint8_t)t->id;
    rosidl_runtime_c__String__assign(&d->transition.label, t->label);
    if (t->start) state_msg(&d->start_state, t->start);
    if (t->goal) state_msg(&d->goal_state, t->goal);
  }
}

/* The services in the order of lifecycle_pending.service. */
static rcl_service_t *service_of(node_lifecycle *lc, int which) {
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  rcl_service_t *all[LIFECYCLE_SERVICES] = {
      &c->srv_change_state, &c->srv_get_state, &c->srv_get_available_states,
      &c->srv_get_available_transitions, &c->srv_get_transition_graph};
  return all[which];
}

static const char *const SERVICE_NAMES[LIFECYCLE_SERVICES] = {
    "change_state", "get_state", "get_available_states", "get_available_transitions",
    "get_transition_graph"};

/* Send one response, made from `p` (the state and outcome when the request was served, the
 * machine's fixed states and transitions): 1 delivered (or its client gone), 0 not (the
 * error reset).  The introspection answers are as rclpy's lifecycle node gives them: every
 * state of the machine (primary and transition states), the transitions of the state, the
 * whole transition graph. */
static int send_one(node_lifecycle *lc, lifecycle_pending *p) {
  rcl_service_t *srv = service_of(lc, p->service);
  const rcl_lifecycle_transition_map_t *map = &lc->sm.transition_map;
  rcl_ret_t ret;
  if (p->service == LC_SRV_CHANGE_STATE) {
    lifecycle_msgs__srv__ChangeState_Response res;
    lifecycle_msgs__srv__ChangeState_Response__init(&res);
    res.success = p->success != 0;
    ret = rcl_send_response(srv, &p->header, &res);
    lifecycle_msgs__srv__ChangeState_Response__fini(&res);
  } else if (p->service == LC_SRV_GET_STATE) {
    lifecycle_msgs__srv__GetState_Response res;
    lifecycle_msgs__srv__GetState_Response__init(&res);
    state_msg(&res.current_state, p->state);
    ret = rcl_send_response(srv, &p->header, &res);
    lifecycle_msgs__srv__GetState_Response__fini(&res);
  } else if (p->service == LC_SRV_AVAILABLE_STATES) {
    lifecycle_msgs__srv__GetAvailableStates_Response res;
    lifecycle_msgs__srv__GetAvailableStates_Response__init(&res);
    if (lifecycle_msgs__msg__State__Sequence__init(&res.available_states, map->states_size))
      for (unsigned int i = 0; i < map->states_size; ++i)
        state_msg(&res.available_states.data[i], &map->states[i]);
    ret = rcl_send_response(srv, &p->header, &res);
    lifecycle_msgs__srv__GetAvailableStates_Response__fini(&res);
  } else { /* get_available_transitions (of the state), get_transition_graph (all) */
    lifecycle_msgs__srv__GetAvailableTransitions_Response res;
    lifecycle_msgs__srv__GetAvailableTransitions_Response__init(&res);
    if (p->service == LC_SRV_AVAILABLE_TRANSITIONS)
      describe_transitions(&res.available_transitions, p->state->valid_transitions,
                           p->state->valid_transition_size);
    else
      describe_transitions(&res.available_transitions, map->transitions, map->transitions_size);
    ret = rcl_send_response(srv, &p->header, &res);
    lifecycle_msgs__srv__GetAvailableTransitions_Response__fini(&res);
  }
  if (ret == RCL_RET_OK) return 1;
  rcutils_reset_error();
  return 0;
}

/* Send, or keep for a later serve (dropped with a line when there is no room). */
static void send_or_keep(node_lifecycle *lc, lifecycle_pending *p) {
  if (send_one(lc, p)) return;
  if (lc->n_pending < LIFECYCLE_PENDING) {
    p->since = mono_s();
    lc->pending[lc->n_pending++] = *p;
  } else {
    fprintf(stderr, "node: the response to a lifecycle %s not delivered (its client's reader "
                    "not matched) and %d others waiting: dropped\n",
            SERVICE_NAMES[p->service], LIFECYCLE_PENDING);
  }
}

/* The kept responses: tried again (may_block) until LIFECYCLE_RESEND_S, else dropped. */
static void resend(node_lifecycle *lc, int may_block) {
  int kept = 0;
  for (int i = 0; i < lc->n_pending; ++i) {
    lifecycle_pending *p = &lc->pending[i];
    if (may_block && send_one(lc, p)) continue;
    if (may_block && mono_s() - p->since < LIFECYCLE_RESEND_S) {
      lc->pending[kept++] = *p;
      continue;
    }
    fprintf(stderr,
            "node: the response to a lifecycle %s not delivered (its client's reader not "
            "matched %s): dropped; the client can ask get_state\n",
            SERVICE_NAMES[p->service], may_block ? "within 10 s" : "before samples came");
  }
  lc->n_pending = kept;
}

/* Every request waiting at service `which` (request type `Req`): `body` run, then answered. */
#define TAKE_ALL(Req, which, body)                                                     \
  do {                                                                                \
    Req req;                                                                          \
    Req##__init(&req);                                                                \
    while (rcl_take_request(service_of(lc, (which)), &p.header, &req) == RCL_RET_OK) { \
      p.service = (which), p.state = lc->sm.current_state;                            \
      body;                                                                           \
      send_or_keep(lc, &p);                                                           \
    }                                                                                 \
    Req##__fini(&req);                                                                \
  } while (0)

void lifecycle_serve(node_lifecycle *lc, int may_block, void (*on)(void *ctx, int event),
                     void *ctx) {
  if (!lc->enabled) return;
  if (lc->n_pending) resend(lc, may_block);
  lifecycle_pending p;
  memset(&p, 0, sizeof p);
  TAKE_ALL(lifecycle_msgs__srv__ChangeState_Request, LC_SRV_CHANGE_STATE, {
    uint8_t id = req.transition.id;
    if (id == 0 && req.transition.label.data) { /* by label: its id from the current state */
      const rcl_lifecycle_transition_t *t =
          rcl_lifecycle_get_transition_by_label(lc->sm.current_state, req.transition.label.data);
      id = t ? (uint8_t)t->id : 0;
    }
    p.success = id != 0 && transition(lc, id, on, ctx);
  });
  TAKE_ALL(lifecycle_msgs__srv__GetState_Request, LC_SRV_GET_STATE, {});
  TAKE_ALL(lifecycle_msgs__srv__GetAvailableStates_Request, LC_SRV_AVAILABLE_STATES, {});
  TAKE_ALL(lifecycle_msgs__srv__GetAvailableTransitions_Request, LC_SRV_AVAILABLE_TRANSITIONS, {});
  TAKE_ALL(lifecycle_msgs__srv__GetAvailableTransitions_Request, LC_SRV_TRANSITION_GRAPH, {});
}

void lifecycle_fini(node_lifecycle *lc, rcl_node_t *node) {
  if (lc->enabled && rcl_lifecycle_state_machine_fini(&lc->sm, node) != RCL_RET_OK)
    rcutils_reset_error();
}
