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

static void serve_introspection(node_lifecycle *lc);

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

rcl_ret_t lifecycle_wait_add(node_lifecycle *lc, rcl_wait_set_t *ws) {
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  rcl_service_t *all[LIFECYCLE_SERVICES] = {
      &c->srv_change_state, &c->srv_get_state, &c->srv_get_available_states,
      &c->srv_get_available_transitions, &c->srv_get_transition_graph};
  rcl_ret_t ret = RCL_RET_OK;
  for (int i = 0; i < LIFECYCLE_SERVICES && ret == RCL_RET_OK; ++i)
    ret = rcl_wait_set_add_service(ws, all[i], NULL);
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

/* Send one response to change_state (p->change) or get_state: 1 delivered (or its client
 * gone), 0 not (the error reset). */
static int send_one(node_lifecycle *lc, lifecycle_pending *p) {
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  rcl_ret_t ret;
  if (p->change) {
    lifecycle_msgs__srv__ChangeState_Response res;
    lifecycle_msgs__srv__ChangeState_Response__init(&res);
    res.success = p->success != 0;
    ret = rcl_send_response(&c->srv_change_state, &p->header, &res);
    lifecycle_msgs__srv__ChangeState_Response__fini(&res);
  } else {
    lifecycle_msgs__srv__GetState_Response res;
    lifecycle_msgs__srv__GetState_Response__init(&res);
    res.current_state.id = (uint8_t)p->state->id;
    rosidl_runtime_c__String__assign(&res.current_state.label, p->state->label);
    ret = rcl_send_response(&c->srv_get_state, &p->header, &res);
    lifecycle_msgs__srv__GetState_Response__fini(&res);
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
    ++lc->dropped;
    fprintf(stderr, "node: a lifecycle response not delivered (its client not matched), "
                    "and %d others waiting: dropped\n", LIFECYCLE_PENDING);
  }
}

/* The kept responses: tried again (may_block) until LIFECYCLE_RESEND_S, else dropped. */
static void resend(node_lifecycle *lc, int may_block) {
  int kept = 0;
  for (int i = 0; i < lc->n_pending; ++i) {
    lifecycle_pending *p = &lc->pending[i];
    if (may_block && send_one(lc, p)) {
      ++lc->resent;
      continue;
    }
    if (may_block && mono_s() - p->since < LIFECYCLE_RESEND_S) {
      lc->pending[kept++] = *p;
      continue;
    }
    ++lc->dropped;
    fprintf(stderr,
            "node: the response to a lifecycle %s not delivered (its client's reader not "
            "matched %s): dropped; the client can ask get_state\n",
            p->change ? "change_state" : "get_state",
            may_block ? "within 10 s" : "before samples came");
  }
  lc->n_pending = kept;
}

void lifecycle_serve(node_lifecycle *lc, int may_block, void (*on)(void *ctx, int event),
                     void *ctx) {
  if (!lc->enabled) return;
  if (lc->n_pending) resend(lc, may_block);
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  lifecycle_pending p;
  memset(&p, 0, sizeof p);
  lifecycle_msgs__srv__ChangeState_Request req;
  lifecycle_msgs__srv__ChangeState_Request__init(&req);
  while (rcl_take_request(&c->srv_change_state, &p.header, &req) == RCL_RET_OK) {
    uint8_t id = req.transition.id;
    if (id == 0 && req.transition.label.data) { /* by label: its id from the current state */
      const rcl_lifecycle_transition_t *t =
          rcl_lifecycle_get_transition_by_label(lc->sm.current_state, req.transition.label.data);
      id = t ? (uint8_t)t->id : 0;
    }
    p.change = 1;
    p.success = id != 0 && transition(lc, id, on, ctx);
    send_or_keep(lc, &p);
  }
  lifecycle_msgs__srv__ChangeState_Request__fini(&req);
  lifecycle_msgs__srv__GetState_Request greq;
  lifecycle_msgs__srv__GetState_Request__init(&greq);
  while (rcl_take_request(&c->srv_get_state, &p.header, &greq) == RCL_RET_OK) {
    p.change = 0;
    p.state = lc->sm.current_state;
    send_or_keep(lc, &p);
  }
  lifecycle_msgs__srv__GetState_Request__fini(&greq);
  serve_introspection(lc);
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

/* The introspection services `ros2 lifecycle list` asks, answered as rclpy's lifecycle node
 * answers them: every state of the machine (primary and transition states), the transitions
 * of the current state, and the whole transition graph. */
static void serve_introspection(node_lifecycle *lc) {
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  const rcl_lifecycle_transition_map_t *map = &lc->sm.transition_map;
  rmw_request_id_t header;
  lifecycle_msgs__srv__GetAvailableStates_Request sreq;
  lifecycle_msgs__srv__GetAvailableStates_Request__init(&sreq);
  while (rcl_take_request(&c->srv_get_available_states, &header, &sreq) == RCL_RET_OK) {
    lifecycle_msgs__srv__GetAvailableStates_Response res;
    lifecycle_msgs__srv__GetAvailableStates_Response__init(&res);
    if (lifecycle_msgs__msg__State__Sequence__init(&res.available_states, map->states_size))
      for (unsigned int i = 0; i < map->states_size; ++i)
        state_msg(&res.available_states.data[i], &map->states[i]);
    if (rcl_send_response(&c->srv_get_available_states, &header, &res) != RCL_RET_OK)
      rcutils_reset_error();
    lifecycle_msgs__srv__GetAvailableStates_Response__fini(&res);
  }
  lifecycle_msgs__srv__GetAvailableStates_Request__fini(&sreq);
  rcl_service_t *srv[2] = {&c->srv_get_available_transitions, &c->srv_get_transition_graph};
  for (int which = 0; which < 2; ++which) {
    lifecycle_msgs__srv__GetAvailableTransitions_Request treq;
    lifecycle_msgs__srv__GetAvailableTransitions_Request__init(&treq);
    while (rcl_take_request(srv[which], &header, &treq) == RCL_RET_OK) {
      lifecycle_msgs__srv__GetAvailableTransitions_Response res;
      lifecycle_msgs__srv__GetAvailableTransitions_Response__init(&res);
      const rcl_lifecycle_state_t *now = lc->sm.current_state;
      if (which == 0)
        describe_transitions(&res.available_transitions, now->valid_transitions,
                             now->valid_transition_size);
      else
        describe_transitions(&res.available_transitions, map->transitions,
                             map->transitions_size);
      if (rcl_send_response(srv[which], &header, &res) != RCL_RET_OK) rcutils_reset_error();
      lifecycle_msgs__srv__GetAvailableTransitions_Response__fini(&res);
    }
    lifecycle_msgs__srv__GetAvailableTransitions_Request__fini(&treq);
  }
}

void lifecycle_fini(node_lifecycle *lc, rcl_node_t *node) {
  if (lc->enabled && rcl_lifecycle_state_machine_fini(&lc->sm, node) != RCL_RET_OK)
    rcutils_reset_error();
}
