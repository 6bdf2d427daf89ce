// The account side of the API: the session (sign in and out), projects and
// their members. Transport, CSRF token and project context are api.ts's.

import { request, type Page } from './api';

export type Role = 'viewer' | 'editor' | 'owner';
export const ROLES: readonly Role[] = ['viewer', 'editor', 'owner'];

export interface User {
  id: string;
  name: string;
  admin: boolean;
}
export interface Session {
  user: User;
  /** Null for callers with a bearer token (the page always has one). */
  csrf_token: string | null;
  personal_project_id: string;
}
export interface Project {
  id: string;
  name: string;
  personal: boolean;
  /** The caller's role in it. */
  role: Role;
  created_at: string;
}
export interface Member {
  user: string;
  role: Role;
}

/** How to sign in: a user name and password, or an API token. */
export type Credentials = { user: string; password: string } | { token: string };

const enc = encodeURIComponent;

export const accounts = {
  // Both answer 401 as the expected "not signed in": quiet (no "sign in again").
  getSession: () => request<Session>('GET', '/api/v1/session', undefined, true),
  signIn: (credentials: Credentials) => request<Session>('POST', '/api/v1/session', credentials, true),
  signOut: () => request<void>('DELETE', '/api/v1/session', undefined, true),

  listProjects: () => request<Page<Project>>('GET', '/api/v1/projects?limit=100&offset=0'),
  createProject: (name: string) => request<Project>('POST', '/api/v1/projects', { name }),

  listMembers: (projectId: string) => request<Page<Member>>('GET', `/api/v1/projects/${enc(projectId)}/members?limit=100&offset=0`),
  setMember: (projectId: string, user: string, role: Role) => request<Member>('POST', `/api/v1/projects/${enc(projectId)}/members`, { user, role }),
  removeMember: (projectId: string, user: string) => request<void>('DELETE', `/api/v1/projects/${enc(projectId)}/members/${enc(user)}`),
};

/** Whether a role may create and delete resources. */
export const canEdit = (role: Role | null | undefined): boolean => role === 'editor' || role === 'owner';
/** Whether a role may manage a project's members. */
export const canManage = (role: Role | null | undefined): boolean => role === 'owner';
