/* amsfe_lifecycle.c: see amsfe_lifecycle.h. */
#include "amsfe_lifecycle.h"

#include <rcl_lifecycle/default_state_machine.h>
#include <rcutils/error_handling.h>
#include <lifecycle_msgs/msg/transition.h>
#include <lifecycle_msgs/msg/transition_event.h>
#include <lifecycle_msgs/srv/change_state.h>
#include <lifecycle_msgs/srv/get_available_states.h>
#include <lifecycle_msgs/srv/get_available_transitions.h>
#include <lifecycle_msgs/srv/get_state.h>
#include <rosidl_runtime_c/string_functions.h>

rcl_ret_t lifecycle_init(node_lifecycle *lc, rcl_node_t *node) {
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
  rcl_ret_t ret = rcl_wait_set_add_service(ws, &c->srv_change_state, NULL);
  if (ret == RCL_RET_OK) ret = rcl_wait_set_add_service(ws, &c->srv_get_state, NULL);
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

void lifecycle_serve(node_lifecycle *lc, void (*on)(void *ctx, int event), void *ctx) {
  if (!lc->enabled) return;
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  rmw_request_id_t header;
  lifecycle_msgs__srv__ChangeState_Request req;
  lifecycle_msgs__srv__ChangeState_Response res;
  lifecycle_msgs__srv__ChangeState_Request__init(&req);
  lifecycle_msgs__srv__ChangeState_Response__init(&res);
  while (rcl_take_request(&c->srv_change_state, &header, &req) == RCL_RET_OK) {
    uint8_t id = req.transition.id;
    if (id == 0 && req.transition.label.data) { /* by label: its id from the current state */
      const rcl_lifecycle_transition_t *t =
          rcl_lifecycle_get_transition_by_label(lc->sm.current_state, req.transition.label.data);
      id = t ? (uint8_t)t->id : 0;
    }
    res.success = id != 0 && transition(lc, id, on, ctx);
    if (rcl_send_response(&c->srv_change_state, &header, &res) != RCL_RET_OK) rcutils_reset_error();
  }
  lifecycle_msgs__srv__ChangeState_Request__fini(&req);
  lifecycle_msgs__srv__ChangeState_Response__fini(&res);
  lifecycle_msgs__srv__GetState_Request greq;
  lifecycle_msgs__srv__GetState_Response gres;
  lifecycle_msgs__srv__GetState_Request__init(&greq);
  lifecycle_msgs__srv__GetState_Response__init(&gres);
  while (rcl_take_request(&c->srv_get_state, &header, &greq) == RCL_RET_OK) {
    gres.current_state.id = (uint8_t)lc->sm.current_state->id;
    rosidl_runtime_c__String__assign(&gres.current_state.label, lc->sm.current_state->label);
    if (rcl_send_response(&c->srv_get_state, &header, &gres) != RCL_RET_OK) rcutils_reset_error();
  }
  lifecycle_msgs__srv__GetState_Request__fini(&greq);
  lifecycle_msgs__srv__GetState_Response__fini(&gres);
}

void lifecycle_fini(node_lifecycle *lc, rcl_node_t *node) {
  if (lc->enabled && rcl_lifecycle_state_machine_fini(&lc->sm, node) != RCL_RET_OK)
    rcutils_reset_error();
}
